"""Gymnasium ids of the GrowSpace environments, registered lazily by entry-point string.

Every registered ``Task`` (``core.task``) gets ``GrowSpace/<env_name>[Continuous]-<Setting>-v0``
for each of its settings, plus its ``extra_envs``; each id also gets the native vector env
(``envs.vector``) as its ``vector_entry_point`` (``gymnasium.make_vec``). Importing this
module imports Gymnasium and the numpy core only, not the environments (nor OpenCV), so that
``import growspace_sim`` stays cheap and the core stays importable without OpenCV.
"""

from __future__ import annotations

import gymnasium as gym

from growspace_sim.core import task as tasks

ENTRY_POINT = 'growspace_sim.envs.env:GrowSpaceEnv'
VECTOR_ENTRY_POINT = 'growspace_sim.envs.vector:GrowSpaceVectorEnv'  # gymnasium.make_vec
VECTOR_ENTRY_POINTS = {  # entry point -> the native vector env that plays the same episodes
    ENTRY_POINT: VECTOR_ENTRY_POINT,
    'growspace_sim.envs.env:make_curriculum': 'growspace_sim.envs.vector:make_curriculum_vector',
}


def env_id(challenge: str, setting: str, continuous: bool = False) -> str:
    """The registered id, e.g. ``GrowSpace/FindPlant-Hard-v0``.

    Raises:
        ValueError: if ``challenge`` names no registered task.
    """
    suffix = 'Continuous' if continuous else ''
    return f'GrowSpace/{tasks.get(challenge).env_name}{suffix}-{setting.capitalize()}-v0'


def register_envs() -> list[str]:
    """Register every task x setting (discrete and continuous) with Gymnasium; idempotent.

    Call it again after registering a task of your own to get its ids.

    Returns:
        All GrowSpace ids.
    """
    specs = {}
    for task in tasks.all_tasks():
        for setting in task.settings:
            for continuous in (False, True):
                specs[env_id(task.name, setting, continuous)] = (
                    ENTRY_POINT,
                    {'challenge': task.name, 'setting': setting, 'continuous': continuous})
        specs.update(task.extra_envs)
    for name, (entry_point, kwargs) in specs.items():
        if name not in gym.registry:
            gym.register(name, entry_point=entry_point,
                         vector_entry_point=VECTOR_ENTRY_POINTS.get(entry_point),
                         kwargs=dict(kwargs))
    return sorted(specs)
