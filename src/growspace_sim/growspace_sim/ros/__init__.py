"""ROS 2 wire layer without rclpy: message types (rosbags) and a Cyclone DDS transport.

Submodules: `types` (typestore, CDR, type hashes), `idl` (cyclonedds type classes), `names`
(rcl name resolution), `qos` (rmw QoS profiles), `dds` (the transport). Only `idl` and `dds`
import cyclonedds.
"""
