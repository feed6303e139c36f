"""The ``sim_node``: one GrowSpace chamber on ROS 2 topics, on rclpy or plain Cyclone DDS.

Modules: ``transport`` (the seam: a small protocol, its Cyclone DDS implementation and the
throttled logger), ``rclpy_transport`` (the same protocol on rclpy, used on a ROS 2 machine),
``params`` (parameters, ROS CLI and params-file parsing), ``chamber_node`` (the node logic,
written once against the seam), ``main`` (the entry point) and ``pub`` (a one-shot publisher
for machines without the ``ros2`` CLI).
"""
