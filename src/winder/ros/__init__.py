"""The ROS side of the contract: the only part of the winder library that
imports rclpy. Every node (and a hardware driver in place of ``sim_node``)
builds on it; the rest of the library never imports it, so it stays usable
without a ROS install."""
