"""Recording: the MCAP bag writer (:mod:`~winder.record.bag`,
:mod:`~winder.record.mcap_storage`) and reader (:mod:`~winder.record.raw` walks
the files, :mod:`~winder.record.reader` decodes them). ROS-free (rosbags, mcap, numpy)."""
