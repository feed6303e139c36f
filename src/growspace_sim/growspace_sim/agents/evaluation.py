"""The one episode loop, and agents played on the same seeded episodes.

``play_episodes`` steps any env-like object with the Gymnasium API (a ``GrowSpaceEnv``, a bridged
``GrowSpaceROS`` env, the in-process node's ``EpisodeRunner``) with any ``Agent``; ``evaluate``
plays several agents on the same seeds of one env id. ``growspace-eval`` (random and oracle per
challenge), ``growspace-compare`` (trained policies beside them), ``growspace-sweep``'s trials,
``growspace-record`` and the benchmark all play their episodes here.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
import math
from typing import Any

import gymnasium as gym
import numpy as np

from growspace_sim.agents.reference import Agent, OracleAgent, RandomAgent
from growspace_sim.core import task as tasks

AGENTS = ('random', 'oracle')  # the reference agents, by name
AgentFactory = Callable[[gym.Env], Agent]  # builds an agent for an env (its action space)


@dataclass(frozen=True)
class Episodes:
    """What one agent scored on a run of seeded episodes."""

    rewards: np.ndarray  # (episodes, steps) float64, zero-padded past an early termination
    success: np.ndarray  # (episodes,) bool, the last step's info['success']
    infos: tuple[dict, ...]  # the last info of every episode

    @property
    def returns(self) -> np.ndarray:
        """Undiscounted return of every episode, shape (episodes,)."""
        return episode_returns(self.rewards)

    @property
    def steps(self) -> int:
        """Steps played, over all episodes."""
        return int(sum(info.get('step', 0) for info in self.infos))


def episode_returns(rewards: np.ndarray) -> np.ndarray:
    """The return of each row of per-step rewards, added step by step in order as an agent
    accumulates it, so every report of the same episodes prints the same number on every
    stack: numpy's pairwise sum and Python 3.12's ``sum`` (compensated) differ in the last bit.
    """
    returns = []
    for row in np.asarray(rewards, np.float64).tolist():
        total = 0.0
        for reward in row:
            total += reward
        returns.append(total)
    return np.array(returns, np.float64)


def play_episodes(env: Any, agent: Agent, seeds: Iterable[int | None], *,
                  options: Mapping[str, Any] | None = None,
                  on_step: Callable[[], None] | None = None) -> Episodes:
    """Play one episode per seed: reset with it, then act until terminated or truncated.

    Args:
        env: Anything with Gymnasium's ``reset(seed=, options=)`` and five-value ``step``.
        agent: Acts on every observation (``agent.act(observation, env)``).
        seeds: One episode per seed; None continues the env's random stream.
        options: Passed to every ``reset`` (e.g. ``{'challenge': 'shape'}`` for a runner).
        on_step: Called before every step (e.g. to pace a realtime recording).

    Returns:
        The rewards of every step, each episode's success and last info.
    """
    rows, infos = [], []
    for seed in seeds:
        observation, info = env.reset(seed=seed, options=dict(options) if options else None)
        rewards, done = [], False
        while not done:
            if on_step is not None:
                on_step()
            observation, reward, terminated, truncated, info = env.step(
                agent.act(observation, env))
            rewards.append(float(reward))
            done = terminated or truncated
        rows.append(rewards)
        infos.append(info)
    width = max((len(r) for r in rows), default=0)
    padded = np.array([r + [0.0] * (width - len(r)) for r in rows], np.float64)
    return Episodes(padded.reshape(len(rows), width),
                    np.array([bool(i.get('success', False)) for i in infos], bool), tuple(infos))


def make_agent(name: str, env: Any, seed: int | None = None) -> Agent:
    """A reference agent by name: ``random`` (actions seeded with ``seed``) or ``oracle`` (which
    refuses, at its first action, a challenge without one: ``has_oracle``).

    Raises:
        ValueError: for another name.
    """
    if name == 'random':
        return RandomAgent(env.action_space, seed)
    if name == 'oracle':
        return OracleAgent()
    raise ValueError(f'agent must be one of {", ".join(AGENTS)}, got {name!r}.')


def has_oracle(challenge: str) -> bool:
    """Whether the challenge's task comes with an oracle (``Task.oracle``; it is optional)."""
    return tasks.get(challenge).oracle is not None


def evaluate(env_name: str, agents: Mapping[str, AgentFactory], seeds: Iterable[int], *,
             env_kwargs: Mapping[str, Any] | None = None) -> dict[str, Episodes]:
    """Every agent plays the same seeded episodes of one env id.

    Args:
        env_name: A registered id, e.g. ``GrowSpace/Control-Easy-v0``.
        agents: Label -> a function that builds the agent for the env.
        seeds: One episode per seed, the same for every agent.
        env_kwargs: Keyword overrides for ``gymnasium.make`` (``SimConfig`` fields, ...).

    Returns:
        Label -> what that agent scored.
    """
    seeds = list(seeds)
    env = gym.make(env_name, **(env_kwargs or {}))
    try:
        return {label: play_episodes(env, build(env), seeds) for label, build in agents.items()}
    finally:
        env.close()


def play_agent(env_name: str, agent: str, episodes: int, seed: int = 0,
               agent_seed: int | None = None,
               env_kwargs: Mapping[str, Any] | None = None) -> Episodes:
    """A reference agent on ``episodes`` episodes (seeds ``seed``, ``seed + 1``, ...): one
    ``growspace-sweep`` trial, or one column of ``growspace-eval``.

    Args:
        env_name: A registered id.
        agent: ``random`` or ``oracle``.
        episodes: Number of episodes.
        seed: Seed of the first episode.
        agent_seed: Seed of the random agent's actions; default ``seed``.
        env_kwargs: Keyword overrides for ``gymnasium.make``.
    """
    action_seed = seed if agent_seed is None else agent_seed
    return evaluate(env_name, {agent: lambda env: make_agent(agent, env, action_seed)},
                    range(seed, seed + episodes), env_kwargs=env_kwargs)[agent]


def mean_se(values: np.ndarray) -> tuple[float, float]:
    """Mean and standard error of the mean (NaN for fewer than two values)."""
    array = np.asarray(values, np.float64)
    se = array.std(ddof=1) / math.sqrt(array.size) if array.size > 1 else float('nan')
    return float(array.mean()), float(se)
