"""The cell's contract, ROS-free: topic names, the nodes' setting tables, the
job description and stream rows, and the CDR payloads on the wire and in bags.

Every node, the recorder, the reader and a third-party driver agree on these;
:mod:`winder.ros` adds what needs rclpy (QoS objects, parameter glue).
"""
