"""Gymnasium environments over a running GrowSpace chamber's ROS 2 topics (issue #4: not yet
implemented; the in-process environments live in ``growspace_sim.envs``)."""
