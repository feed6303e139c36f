"""Random vs oracle returns per challenge and setting (``growspace-eval``).

Both agents play the same seeded episodes; the table gives the mean 50-step return with its
standard error over the episodes. Usage::

    growspace-eval --episodes 100            # the README table (about a minute on one core)
    growspace-eval --episodes 5 --csv out.csv
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

import growspace_sim  # noqa: F401  (registers the ids)
from growspace_sim.agents.reference import Agent, OracleAgent, RandomAgent, play_episodes
from growspace_sim.core import task as tasks
from growspace_sim.envs.registration import env_id

AGENTS = ('random', 'oracle')
COLUMNS = ('challenge', 'setting', 'episodes', 'random_mean', 'random_se', 'oracle_mean',
           'oracle_se', 'oracle_success')


@dataclass(frozen=True)
class Row:
    challenge: str
    setting: str
    episodes: int
    random_mean: float
    random_se: float
    oracle_mean: float
    oracle_se: float
    oracle_success: float  # fraction of oracle episodes whose last step reached the goal


@dataclass(frozen=True)
class Episodes:
    """What one agent scored on a run of seeded episodes."""

    rewards: np.ndarray  # (episodes, steps) float64, reward of every step
    success: np.ndarray  # (episodes,) bool, the last step's info['success']

    @property
    def returns(self) -> np.ndarray:
        """Undiscounted return of every episode, shape (episodes,)."""
        return self.rewards.sum(axis=1)


def make_agent(name: str, env: gym.Env, seed: int) -> Agent:
    """A reference agent by name: ``random`` (actions seeded with ``seed``) or ``oracle``."""
    if name == 'random':
        return RandomAgent(env.action_space, seed)
    if name == 'oracle':
        return OracleAgent()
    raise ValueError(f'agent must be one of {", ".join(AGENTS)}, got {name!r}.')


def play_agent(env_name: str, agent: str, episodes: int, seed: int = 0,
               agent_seed: int | None = None, env_kwargs: dict | None = None) -> Episodes:
    """Play ``episodes`` episodes (seeds ``seed``, ``seed + 1``, ...) with a reference agent.

    Used by ``growspace-eval`` and by every evaluation trial of ``growspace-sweep``.

    Args:
        env_name: A registered id, e.g. ``GrowSpace/Control-Easy-v0``.
        agent: ``random`` or ``oracle``.
        episodes: Number of episodes.
        seed: Seed of the first episode.
        agent_seed: Seed of the random agent's actions; default ``seed``.
        env_kwargs: Keyword overrides for ``gymnasium.make`` (``SimConfig`` fields, ...).

    Returns:
        Per-step rewards and per-episode success.
    """
    env = gym.make(env_name, **(env_kwargs or {}))
    try:
        player = make_agent(agent, env, seed if agent_seed is None else agent_seed)
        rewards, infos = play_episodes(env, player, range(seed, seed + episodes))
    finally:
        env.close()
    return Episodes(rewards, np.array([bool(i.get('success', False)) for i in infos]))


def evaluate(challenge: str, setting: str, episodes: int, seed: int = 0) -> Row:
    """Play ``episodes`` seeded episodes with each agent on the discrete env."""
    name = env_id(challenge, setting)
    random_runs = play_agent(name, 'random', episodes, seed)
    oracle_runs = play_agent(name, 'oracle', episodes, seed)
    return Row(challenge, setting, episodes, *mean_se(random_runs.returns),
               *mean_se(oracle_runs.returns), float(oracle_runs.success.mean()))


def mean_se(values: np.ndarray) -> tuple[float, float]:
    """Mean and standard error of the mean (NaN for fewer than two values)."""
    array = np.asarray(values, np.float64)
    se = array.std(ddof=1) / math.sqrt(array.size) if array.size > 1 else float('nan')
    return float(array.mean()), float(se)


def markdown(rows: list[Row]) -> str:
    lines = ['| challenge | setting | random | oracle | oracle success |',
             '|---|---|---|---|---|']
    for r in rows:
        lines.append(f'| {r.challenge} | {r.setting} | {r.random_mean:.2f} ± {r.random_se:.2f} '
                     f'| {r.oracle_mean:.2f} ± {r.oracle_se:.2f} | {r.oracle_success:.0%} |')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--episodes', type=int, default=100, help='episodes per agent and case')
    parser.add_argument('--seed', type=int, default=0, help='first episode seed')
    parser.add_argument('--challenges', default=','.join(tasks.names()))
    parser.add_argument('--settings', default=','.join(tasks.SETTINGS))
    parser.add_argument('--csv', help='also write the rows to this CSV file')
    args = parser.parse_args(argv)
    if args.episodes < 2:
        parser.error(f'--episodes must be >= 2 for a standard error, got {args.episodes}')
    challenges = args.challenges.split(',')
    settings = args.settings.split(',')
    for name, values, allowed in (('challenges', challenges, tasks.names()),
                                  ('settings', settings, tasks.SETTINGS)):
        unknown = sorted(set(values) - set(allowed))
        if unknown:
            parser.error(f'--{name}: unknown {unknown}; allowed: {", ".join(allowed)}')
    start = time.perf_counter()
    rows = []
    for challenge in challenges:
        for setting in settings:
            rows.append(evaluate(challenge, setting, args.episodes, args.seed))
            print(f'{challenge}/{setting} done', file=sys.stderr)
    print(f'Mean 50-step return ± s.e. over {args.episodes} seeded episodes '
          f'(seeds {args.seed}..{args.seed + args.episodes - 1}), '
          f'{time.perf_counter() - start:.0f} s\n')
    print(markdown(rows))
    if args.csv:
        with open(args.csv, 'w', newline='') as f:
            writer = csv.writer(f)
            writer.writerow(COLUMNS)
            for r in rows:
                writer.writerow([getattr(r, c) for c in COLUMNS])
    return 0


if __name__ == '__main__':
    sys.exit(main())
