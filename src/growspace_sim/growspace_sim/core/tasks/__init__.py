"""The built-in challenges, one module each, registered on import (paper order).

``common`` holds what they share: layout draws, the distance and Jaccard rewards, oracle steering.
"""

from growspace_sim.core.tasks import control, find_plant, fairness, shape  # noqa: F401
from growspace_sim.core.tasks.common import distance_reward, jaccard

__all__ = ['distance_reward', 'jaccard']
