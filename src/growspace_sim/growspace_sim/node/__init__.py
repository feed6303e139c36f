"""The ``sim_node``: one GrowSpace chamber on ROS 2 topics (rclpy), or in process.

Modules: ``interface`` (the topic and QoS table, the ``chamber/config`` payload and the
recording metadata: the node's wire contract, shared with the recorder and replay),
``transport`` (the seam: a small protocol and the throttled logger), ``rclpy_transport`` (the
protocol on rclpy), ``local`` (the same protocol in process, for ``episode_runner``) and
``fake`` (``local`` plus what tests inspect), ``params`` (parameters and params files),
``chamber_node`` (the node logic, written once against the seam), ``main`` (the entry point)
and ``pub`` (a one-shot publisher for machines without the ``ros2`` CLI).
"""
