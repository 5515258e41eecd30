"""Recording: the MCAP bag writer (:mod:`~winder.record.bag`,
:mod:`~winder.record.mcap_storage`) and reader (:mod:`~winder.record.reader`).
ROS-free (rosbags, mcap, numpy)."""
