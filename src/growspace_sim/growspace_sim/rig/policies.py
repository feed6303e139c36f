"""The policies an experiment runs, and the simulated twin that the oracle acts on.

A policy answers ``act(observation, twin) -> action`` (a discrete action index). The twin is a
``Simulation`` stepped with the same seed and actions as the chamber, through the node's own
command path (``convert.apply_command``), so on ``sim_node`` it is the chamber bit for bit; on
the rig it is the plant the simulator would have grown. The oracle needs the privileged state
the chamber does not publish (the photons, the target), so it acts on the twin, as it does in
the simulator; the other policies ignore it. Every policy here gives the same action for the
same episode, step and observation, so a resumed run acts as the uninterrupted one would have.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from growspace_sim.core.chamber import Chamber, StepOutcome
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import BEAM_ACTIONS, SPOT_ACTIONS
from growspace_sim.ros import convert
from growspace_sim.simulation import Simulation


class Twin:
    """The simulated episode beside the chamber: reset and stepped with the runner's actions.

    Has what ``agents.OracleAgent`` reads of an env (``unwrapped``, ``chamber``,
    ``continuous``).

    Args:
        cfg: The run's chamber configuration.
        digit_source: Shape targets' source.
    """

    continuous = False

    def __init__(self, cfg: SimConfig, digit_source: str = 'auto') -> None:
        self.sim = Simulation(cfg, digit_source)
        self.episode = -1  # the run's 0-based episode index

    @property
    def unwrapped(self) -> Twin:
        return self

    @property
    def chamber(self) -> Chamber:
        return self.sim.chamber

    @property
    def n_actions(self) -> int:
        return len(SPOT_ACTIONS if self.sim.cfg.uses_spotlight else BEAM_ACTIONS)

    def reset(self, episode: int, seed: int) -> StepOutcome:
        self.episode = episode
        return self.sim.reset(seed=seed)

    def step(self, action: int) -> StepOutcome:
        """Apply a discrete action as ``sim_node`` applies a LightCommand, then grow."""
        convert.apply_command(self.sim, convert.discrete_command_msg(int(action), 0, 0, ''))
        return self.sim.step()


class Policy(Protocol):
    def act(self, observation: np.ndarray | None, twin: Twin) -> int:
        """The discrete action for this observation (the twin gives the step and state)."""


class OraclePolicy:
    """The challenge's oracle, acting on the twin."""

    def __init__(self) -> None:
        from growspace_sim.agents import OracleAgent

        self.agent = OracleAgent()

    def act(self, observation: np.ndarray | None, twin: Twin) -> int:
        return int(self.agent.act(observation, twin))


class RandomPolicy:
    """Uniform random actions, drawn from (seed, episode, step): a resume draws the same."""

    def __init__(self, seed: int) -> None:
        self.seed = seed

    def act(self, observation: np.ndarray | None, twin: Twin) -> int:
        rng = np.random.default_rng([self.seed, twin.episode, twin.chamber.steps])
        return int(rng.integers(twin.n_actions))


class ReplayPolicy:
    """The discrete actions of a recording's episodes: run episode i plays recorded episode
    i modulo their number, step by step.

    Raises:
        ValueError: The recording has no episode with steps, or a command is not discrete.
    """

    def __init__(self, path: str) -> None:
        from growspace_sim.replay import Bag, read_episodes

        with Bag(path) as bag:
            episodes = [e for e in read_episodes(bag) if e.n_steps]
        self.actions: list[list[int]] = []
        for episode in episodes:
            actions = []
            for record in episode.stepped:
                step_id = int(record.result.step_id)
                command = next((c for c in record.commands if int(c.step_id) == step_id), None)
                if command is None or int(command.mode) != convert.MODE_DISCRETE:
                    raise ValueError(f'policy_path = {path!r}: episode {episode.index} step '
                                     f'{int(record.result.step)} has no discrete command to '
                                     f'replay.')
                actions.append(int(command.action))
            self.actions.append(actions)
        if not self.actions:
            raise ValueError(f'policy_path = {path!r} holds no episode with steps to replay.')

    def act(self, observation: np.ndarray | None, twin: Twin) -> int:
        actions = self.actions[twin.episode % len(self.actions)]
        step = twin.chamber.steps
        if step >= len(actions):
            raise ValueError(f'the replayed episode has {len(actions)} steps; the run asks '
                             f'for step {step + 1}.')
        return actions[step]


class ModelPolicy:
    """A growspace-train run (Stable-Baselines3 model), deterministic actions."""

    def __init__(self, path: str) -> None:
        from growspace_sim.learn.train import load_model

        self.model = load_model(path, device='cpu')

    def act(self, observation: np.ndarray | None, twin: Twin) -> int:
        if observation is None:
            raise ValueError('the model policy needs an observation, and none is known.')
        action, _ = self.model.predict(observation, deterministic=True)
        return int(action)


def make_policy(kind: str, path: str, seed: int) -> Any:
    """The policy of a run's settings (``RunSettings.policy`` and ``policy_path``).

    Raises:
        ValueError: An unknown kind, or a path that does not hold what the kind needs.
    """
    if kind == 'oracle':
        return OraclePolicy()
    if kind == 'random':
        return RandomPolicy(seed)
    if kind == 'replay':
        return ReplayPolicy(path)
    if kind == 'model':
        return ModelPolicy(path)
    raise ValueError(f'policy = {kind!r}; allowed: oracle, random, replay, model.')
