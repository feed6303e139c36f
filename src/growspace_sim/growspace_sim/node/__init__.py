"""The ``sim_node``: one GrowSpace chamber on ROS 2 topics (rclpy), or in process.

Modules: ``transport`` (the seam: a small protocol and the throttled logger), ``rclpy_transport``
(the protocol on rclpy), ``local`` (the same protocol in process) and ``fake`` (``local`` plus
what tests inspect), ``params`` (parameters and params files), ``chamber_node`` (the node logic,
written once against the seam), ``episode_runner`` (an in-process lockstep client of it),
``main`` (the entry point and the run loop every node shares) and ``view_node``. The wire
contract they speak (topics, QoS, messages) is ``growspace_sim.ros``.
"""
