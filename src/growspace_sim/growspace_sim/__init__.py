"""GrowSpace chamber simulation: a pure core, an OpenCV renderer, Gymnasium envs, ROS adapters.

Importing the package registers the Gymnasium ids (``GrowSpace/Control-Easy-v0`` ...) when
Gymnasium is installed, so subprocess vector-env workers find them; the ROS node does not need
Gymnasium.
"""

__version__ = '0.1.0'

try:
    import gymnasium  # noqa: F401
except ImportError:  # a ROS machine running only the node
    pass
else:
    from growspace_sim.envs.registration import register_envs

    register_envs()
