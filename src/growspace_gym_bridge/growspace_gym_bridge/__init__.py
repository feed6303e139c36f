"""Gymnasium environments that play a GrowSpace chamber through its ROS 2 topics.

``GrowSpaceBridgeEnv`` (in ``growspace_gym_bridge.envs``) drives a lockstep ``sim_node`` by
publishing resets and light commands and waiting for the replies with matching ids; the
in-process twins live in ``growspace_sim.envs.env``. Importing this package registers the ids
``GrowSpaceROS/Control-Easy-v0`` ... (see ``registration``) and imports nothing heavy.
"""

from __future__ import annotations

__version__ = '0.1.0'

from growspace_gym_bridge.errors import (  # noqa: E402
    BridgeError, BridgeTimeout, CommandRejected, NodeDied)

try:
    import gymnasium  # noqa: F401
except ImportError:  # pragma: no cover - the node alone does not need Gymnasium
    pass
else:
    from growspace_gym_bridge.registration import register_bridge_envs

    register_bridge_envs()

__all__ = ['BridgeError', 'BridgeTimeout', 'CommandRejected', 'NodeDied', '__version__']
