#!/usr/bin/env python3
"""Steps/s of the bridged env (``GrowSpaceROS/*``) vs the in-process env, in one run.

Method: control easy (``--id`` to change), random discrete actions (seeded), 50-step
episodes ended by a seeded reset that counts in the time. Rows: one env, and a vector of 2
(Sync; Async with spawned workers). Bridged envs start their own lockstep nodes (one per
sub-env, rclpy, loopback only, a random domain). ``no state`` is the bridged env with
``with_state=False`` (no plant/light state in ``info``; the node then skips building them).
Each figure is the best of ``--repeats`` runs of ``--episodes`` episodes, after one warm-up
episode. A vector step counts as 2 env steps.

Usage (workspace sourced, e.g. through ``./run.sh``'s environment):
    python scripts/bench_bridge.py [--episodes 10] [--repeats 3]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
import os
import random
import time
from typing import Any

import numpy as np

from bench_common import cpu_seconds

EPISODE = 50


def run_single(env: Any, episodes: int, seed: int) -> float:
    rng = np.random.default_rng(seed)
    n = env.action_space.n
    env.reset(seed=seed)
    for _ in range(EPISODE):  # warm-up: connection, caches
        env.step(int(rng.integers(n)))
    start = time.perf_counter()
    for episode in range(episodes):
        env.reset(seed=seed + episode)
        for _ in range(EPISODE):
            env.step(int(rng.integers(n)))
    return episodes * EPISODE / (time.perf_counter() - start)


def run_vector(vec: Any, episodes: int, seed: int) -> float:
    rng = np.random.default_rng(seed)
    n = vec.single_action_space.n
    size = vec.num_envs
    vec.reset(seed=[seed + i for i in range(size)])
    steps = 0
    start = None
    # Autoreset (next-step mode) spends one call per episode on the reset: count env steps.
    for call in range((episodes + 1) * (EPISODE + 1)):
        if call == EPISODE + 1:
            start, steps = time.perf_counter(), 0
        vec.step(rng.integers(n, size=size))
        steps += size
    return steps / (time.perf_counter() - start)


def best(make: Callable[[], Any], run: Callable[..., float], episodes: int, repeats: int,
         seed: int) -> float:
    env = make()
    try:
        return max(run(env, episodes, seed) for _ in range(repeats))
    finally:
        env.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n', 1)[0])
    parser.add_argument('--episodes', type=int, default=10)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--id', default='Control-Easy-v0', help='id without its prefix')
    args = parser.parse_args()
    from growspace_sim.ros import loopback

    loopback.confine()
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(1, 101)))

    import gymnasium as gym

    import growspace_gym_bridge  # noqa: F401 - registers GrowSpaceROS/*
    import growspace_sim  # noqa: F401 - registers GrowSpace/*

    local, bridged = f'GrowSpace/{args.id}', f'GrowSpaceROS/{args.id}'
    e, r, s = args.episodes, args.repeats, args.seed

    def vec(name: str, mode: str, **kwargs: Any) -> Callable[[], Any]:
        vector_kwargs = {'context': 'spawn'} if mode == 'async' else {}
        return lambda: gym.make_vec(name, 2, vectorization_mode=mode,
                                    vector_kwargs=vector_kwargs, **kwargs)

    rows = [
        ('single', best(lambda: gym.make(local), run_single, e, r, s),
         best(lambda: gym.make(bridged), run_single, e, r, s),
         best(lambda: gym.make(bridged, with_state=False), run_single, e, r, s)),
        ('vector 2, Sync', best(vec(local, 'sync'), run_vector, e, r, s),
         best(vec(bridged, 'sync'), run_vector, e, r, s),
         best(vec(bridged, 'sync', with_state=False), run_vector, e, r, s)),
        ('vector 2, Async', best(vec(local, 'async'), run_vector, e, r, s),
         best(vec(bridged, 'async'), run_vector, e, r, s),
         best(vec(bridged, 'async', with_state=False), run_vector, e, r, s)),
    ]
    print(f'{bridged} vs {local}: steps/s, best of {r} x {e} episodes, {os.cpu_count()} CPUs')
    print('| setup | in-process | bridged | bridged / in-process | bridged, no state | ratio |')
    print('|---|---|---|---|---|---|')
    for name, inproc, full, lean in rows:
        print(f'| {name} | {inproc:,.0f} | {full:,.0f} | {full / inproc:.0%} | {lean:,.0f} | '
              f'{lean / inproc:.0%} |')
    env = gym.make(bridged)
    try:
        env.reset(seed=s)
        cpu, node_cpu = time.process_time(), cpu_seconds(env.unwrapped.node_pid)
        run_single(env, e, s)
        steps = (e + 1) * EPISODE
        client = (time.process_time() - cpu) / steps * 1e6
        node = (cpu_seconds(env.unwrapped.node_pid) - node_cpu) / steps * 1e6
        print(f'CPU per step, one bridged env: client {client:.0f} us, node {node:.0f} us')
    finally:
        env.close()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
