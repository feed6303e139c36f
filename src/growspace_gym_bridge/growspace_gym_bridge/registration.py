"""Gymnasium ids of the bridged envs: ``GrowSpaceROS/<Challenge>[Continuous]-<Setting>-v0``.

Each takes the same kwargs as ``GrowSpaceBridgeEnv`` (e.g. ``namespace=`` to attach to a running
node); without them every env starts its own node. Registered by importing the package, so
vector-env workers that import it find them.
"""

from __future__ import annotations

import gymnasium as gym

from growspace_sim.core import task as tasks
from growspace_sim.envs.registration import env_id

PREFIX = 'GrowSpaceROS'
ENTRY_POINT = 'growspace_gym_bridge.envs:GrowSpaceBridgeEnv'


def bridge_id(challenge: str, setting: str, continuous: bool = False) -> str:
    """The bridged twin of an in-process id, e.g. ``GrowSpaceROS/Control-Easy-v0``."""
    name = env_id(challenge, setting, continuous).split('/', 1)[1]
    return f'{PREFIX}/{name}'


def register_bridge_envs() -> list[str]:
    """Register every task x setting (discrete and continuous); idempotent.

    Returns:
        All bridged ids.
    """
    ids = []
    for task in tasks.all_tasks():
        for setting in task.settings:
            for continuous in (False, True):
                name = bridge_id(task.name, setting, continuous)
                ids.append(name)
                if name not in gym.registry:
                    gym.register(name, entry_point=ENTRY_POINT, kwargs={
                        'challenge': task.name, 'setting': setting, 'continuous': continuous})
    return sorted(ids)
