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
from growspace_sim.agents import OracleAgent, RandomAgent, run_episode
from growspace_sim.core import task as tasks
from growspace_sim.registration import env_id

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


def evaluate(challenge: str, setting: str, episodes: int, seed: int = 0) -> Row:
    """Play ``episodes`` seeded episodes with each agent on the discrete env."""
    env = gym.make(env_id(challenge, setting))
    seeds = [seed + i for i in range(episodes)]
    random_agent = RandomAgent(env.action_space, seed)
    random_returns = [run_episode(env, random_agent, s)[0] for s in seeds]
    oracle = OracleAgent()
    oracle_runs = [run_episode(env, oracle, s) for s in seeds]
    env.close()
    oracle_returns = [r for r, _ in oracle_runs]
    success = float(np.mean([info['success'] for _, info in oracle_runs]))
    return Row(challenge, setting, episodes, *_mean_se(random_returns),
               *_mean_se(oracle_returns), success)


def _mean_se(values: list[float]) -> tuple[float, float]:
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
