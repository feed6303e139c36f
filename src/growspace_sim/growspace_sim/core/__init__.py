"""The simulation core: pure numpy, no ROS, no OpenCV, no middleware."""

from growspace_sim.core.chamber import Chamber, StepOutcome
from growspace_sim.core.config import CHALLENGES, SETTINGS, SimConfig
from growspace_sim.core.light import BEAM_ACTIONS, SPOT_ACTIONS, Light

__all__ = ['BEAM_ACTIONS', 'CHALLENGES', 'Chamber', 'Light', 'SETTINGS', 'SPOT_ACTIONS',
           'SimConfig', 'StepOutcome']
