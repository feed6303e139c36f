"""Reference agents: uniform random actions, and the challenge's oracle.

The oracles follow the GrowSpace paper's appendix; each lives beside its challenge's ``Task``
(``core/tasks/``: control and find_plant steer the plant's lead node to the target, fairness
alternates the beam between the plants, shape fills the digit bottom-up). They read the
privileged chamber state (target, plant nodes) that a learning agent only sees as pixels, and
act through the discrete action space, as an agent would.
"""

from __future__ import annotations

from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from growspace_sim.core.task import Oracle, Task


class Agent(Protocol):
    def act(self, observation: np.ndarray, env: gym.Env) -> Any:
        """The action for this observation (``env`` gives oracles the privileged state)."""


class RandomAgent:
    """Uniform random actions from the env's action space, seeded for reproducibility."""

    def __init__(self, action_space: gym.Space, seed: int | None = None) -> None:
        self.action_space = action_space
        self.action_space.seed(seed)

    def act(self, observation: np.ndarray, env: gym.Env) -> Any:
        return self.action_space.sample()


class OracleAgent:
    """The oracle of the env's challenge (``Task.oracle``), discrete actions only.

    ``env`` is anything whose ``unwrapped`` has ``continuous`` and ``chamber``: a Gymnasium
    env of this package or an ``EpisodeRunner``. One oracle per challenge is kept for the agent's
    life (an oracle may remember things between steps).
    """

    def __init__(self) -> None:
        self._oracles: dict[Task, Oracle] = {}

    def act(self, observation: np.ndarray, env: gym.Env) -> int:
        """The oracle's action for the env's current state.

        Raises:
            ValueError: for a continuous env, or a challenge without an oracle.
        """
        base = env.unwrapped
        if base.continuous:
            raise ValueError('OracleAgent acts through discrete actions; use a discrete env id.')
        chamber = base.chamber
        task = chamber.task
        oracle = self._oracles.get(task)
        if oracle is None:
            if task.oracle is None:
                raise ValueError(f'challenge {task.name!r} has no oracle (Task.oracle is None).')
            oracle = self._oracles[task] = task.oracle()
        return oracle.act(chamber)
