"""The ``sim_node``: one GrowSpace chamber on ROS 2 topics, on rclpy or plain Cyclone DDS.

Modules: ``interface`` (the topic and QoS table, the ``chamber/config`` payload and the
recording metadata: the node's wire contract, shared with the recorder and replay),
``transport`` (the seam: a small protocol, its Cyclone DDS implementation and the throttled
logger), ``rclpy_transport`` (the same protocol on rclpy, used on a ROS 2 machine), ``local``
(the same protocol in process, for ``episode_runner``) and ``fake`` (``local`` plus what tests
inspect), ``params`` (parameters, ROS CLI and params-file parsing), ``chamber_node`` (the node
logic, written once against the seam), ``main`` (the entry point) and ``pub`` (a one-shot
publisher for machines without the ``ros2`` CLI).
"""
