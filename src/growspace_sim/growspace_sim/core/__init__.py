"""The simulation core: numpy and numba kernels; no ROS, no OpenCV, no middleware."""

from growspace_sim.core.chamber import Chamber, StepOutcome
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import BEAM_ACTIONS, SPOT_ACTIONS, Light
from growspace_sim.core.state import ChamberState
from growspace_sim.core.task import SETTINGS, Layout, Task, register
from growspace_sim.core import tasks  # noqa: F401,I100  (registers the built-in challenges)

__all__ = ['BEAM_ACTIONS', 'Chamber', 'ChamberState', 'Layout', 'Light', 'SETTINGS',
           'SPOT_ACTIONS', 'SimConfig', 'StepOutcome', 'Task', 'register']
