"""The wire: ROS 2 data without rclpy, and the chamber's contract on it.

Submodules: ``types`` (typestore, CDR, type hashes), ``qos`` (QoS profiles and their rosbag2
YAML), ``names`` (rcl name resolution for the in-process node), ``convert`` (simulation state
<-> messages: the only module that knows both), ``interface`` (the chamber's topic table, its
``chamber/config`` payload and the recording metadata) and ``loopback`` (the network rule: what
we start stays on this host). None of them imports rclpy, so recording and replay run anywhere.
"""
