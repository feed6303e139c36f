"""ROS 2 data without rclpy: message types and CDR (rosbags), QoS profiles, name rules.

Submodules: `types` (typestore, CDR, type hashes), `qos` (QoS profiles and their rosbag2 YAML),
`names` (rcl name resolution for the in-process node) and `loopback` (the network rule: what we
start stays on this host). None of them imports rclpy, so recording and replay run anywhere.
"""
