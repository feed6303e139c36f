"""Gymnasium ids of the GrowSpace environments, registered lazily by entry-point string.

Importing this module imports Gymnasium only, not the environments (nor OpenCV), so that
``import growspace_sim`` stays cheap and the core stays importable without OpenCV.
"""

from __future__ import annotations

import gymnasium as gym

CHALLENGE_IDS = {'control': 'Control', 'find_plant': 'FindPlant', 'fairness': 'Fairness',
                 'shape': 'Shape'}


def env_id(challenge: str, setting: str, continuous: bool = False) -> str:
    """The registered id, e.g. ``GrowSpace/FindPlant-Hard-v0``."""
    suffix = 'Continuous' if continuous else ''
    return f'GrowSpace/{CHALLENGE_IDS[challenge]}{suffix}-{setting.capitalize()}-v0'


def register_envs() -> list[str]:
    """Register every challenge x setting (discrete and continuous) with Gymnasium; idempotent.

    Returns:
        All GrowSpace ids.
    """
    specs = {'GrowSpace/Shape-AllDigits-v0': ('growspace_sim.envs:GrowSpaceEnv',
                                              {'challenge': 'shape', 'digits': tuple(range(10))}),
             'GrowSpace/Shape-Curriculum-v0': ('growspace_sim.envs:make_curriculum', {})}
    for challenge in CHALLENGE_IDS:
        for setting in ('easy', 'hard'):
            for continuous in (False, True):
                specs[env_id(challenge, setting, continuous)] = (
                    'growspace_sim.envs:GrowSpaceEnv',
                    {'challenge': challenge, 'setting': setting, 'continuous': continuous})
    for name, (entry_point, kwargs) in specs.items():
        if name not in gym.registry:
            gym.register(name, entry_point=entry_point, kwargs=kwargs)
    return sorted(specs)
