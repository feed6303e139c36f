#!/usr/bin/env python3
"""What Stable-Baselines3 sees: env steps/s through SB3's ``VecEnv`` interface, in one run.

Two ways to give SB3 N chambers, alternated round by round, best round each (noise on a shared
VM only slows a round down):
- ``dummy``: ``make_vec_env`` = ``DummyVecEnv`` over N ``GrowSpaceEnv``, each in ``Monitor``
  (``growspace-train``'s default);
- ``native``: ``NativeVecEnv`` over one ``GrowSpaceVectorEnv``, in ``VecMonitor``
  (``growspace-train --vec native``).
Random actions drawn beforehand; steps/s of process CPU, so pin the process to one core
(``taskset -c 1``). Also times a short PPO run on each (rollouts and updates, one torch thread).

Needs the learn extra (requirements-learn.txt). Usage (workspace sourced):
    taskset -c 1 python scripts/bench_sb3_vec.py [--env GrowSpace/Control-Easy-v0]
        [--num-envs 16,64] [--steps 20000] [--rounds 3] [--ppo-steps 4096]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time

import numpy as np
from stable_baselines3.common.env_util import make_vec_env
import torch

import growspace_sim  # noqa: F401  (registers the ids)
from growspace_sim.learn import train

KINDS = ('dummy', 'native')


def make(kind: str, env_id: str, n: int):
    return make_vec_env(env_id, n_envs=n, seed=0) if kind == 'dummy' else \
        train.make_env(env_id, n, 0, vec='native')


def env_steps_per_s(kind: str, env_id: str, n: int, steps: int) -> float:
    env = make(kind, env_id, n)
    actions = np.random.default_rng(0).integers(0, env.action_space.n, (steps // n, n))
    env.reset()
    start = time.process_time()
    for action in actions:
        env.step(action)
    cpu = time.process_time() - start
    env.close()
    return actions.size / cpu


def ppo_steps_per_s(kind: str, env_id: str, n: int, steps: int) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        start = time.process_time()
        train.train('ppo', env_id, steps, seed=0, out=tmp, n_envs=n, device='cpu',
                    hp={'n_steps': max(steps // (2 * n), 8), 'batch_size': 256, 'n_epochs': 1},
                    progress_bar=False, vec=kind)
        return steps / (time.process_time() - start)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--env', default='GrowSpace/Control-Easy-v0')
    parser.add_argument('--num-envs', default='16,64')
    parser.add_argument('--steps', type=int, default=20_000, help='env steps per round')
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--ppo-steps', type=int, default=4096, help='0 skips the PPO runs')
    args = parser.parse_args()
    torch.set_num_threads(1)
    sizes = [int(n) for n in args.num_envs.split(',')]
    env_best = {(k, n): 0.0 for k in KINDS for n in sizes}
    ppo_best = dict(env_best)
    env_steps_per_s('native', args.env, sizes[0], sizes[0] * 60)  # warm caches (digits, numba)
    for _ in range(args.rounds):
        for n in sizes:
            for kind in KINDS:
                env_best[kind, n] = max(env_best[kind, n],
                                        env_steps_per_s(kind, args.env, n, args.steps))
                if args.ppo_steps:
                    ppo_best[kind, n] = max(ppo_best[kind, n],
                                            ppo_steps_per_s(kind, args.env, n, args.ppo_steps))
    print(f'{args.env}: SB3 VecEnv steps per CPU second, best of {args.rounds} rounds, '
          f'torch {torch.__version__}, 1 thread')
    print('| envs | DummyVecEnv | NativeVecEnv | ratio | PPO, Dummy | PPO, Native | ratio |')
    print('|---|---|---|---|---|---|---|')
    for n in sizes:
        d, v = env_best['dummy', n], env_best['native', n]
        pd, pv = ppo_best['dummy', n], ppo_best['native', n]
        ppo = f'{pd:,.0f} | {pv:,.0f} | {pv / pd:.2f}x' if args.ppo_steps else '- | - | -'
        print(f'| {n} | {d:,.0f} | {v:,.0f} | {v / d:.2f}x | {ppo} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
