#!/usr/bin/env python3
"""Lockstep round trip through sim_node over loopback DDS vs the in-process env, same run.

Method: control easy, discrete random actions (seeded), 50-step episodes. The node runs in a
child process (lockstep, on a random domain, loopback only); the client sends a LightCommand
and waits for both its StepResult and its Image before the next one; episodes end with a reset
that is waited for too. The in-process figure is ``gymnasium.make('GrowSpace/Control-Easy-v0')``
stepping the same way (obs + reward). Steps/s counts steps only, reset time included. Each
figure is the best of ``--repeats`` runs of ``--episodes`` episodes.

Usage (from the workspace root):
    PYTHONPATH=src/growspace_sim python scripts/bench_node.py [--episodes 20] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import random
import subprocess
import sys
import time

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EPISODE = 50
TIMEOUT_S = 10.0


def in_process(episodes: int, seed: int) -> float:
    import gymnasium as gym

    import growspace_sim  # noqa: F401 - registers the ids

    env = gym.make('GrowSpace/Control-Easy-v0')
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    start = time.perf_counter()
    for _ in range(episodes):
        env.reset()
        for _ in range(EPISODE):
            env.step(int(rng.integers(5)))
    return episodes * EPISODE / (time.perf_counter() - start)


class Client:
    def __init__(self, ctx, qos_cmd, qos_obs) -> None:
        from growspace_sim.ros import types

        self.types = types
        self.cmd = ctx.create_publisher(types.LIGHT_COMMAND, 'light/command', qos_cmd)
        self.rst = ctx.create_publisher(types.RESET_REQUEST, 'reset', qos_cmd)
        self.res = ctx.create_subscription(types.STEP_RESULT, 'step_result', qos_obs)
        self.img = ctx.create_subscription('sensor_msgs/msg/Image', 'camera/image_raw', qos_obs)
        for endpoint in (self.cmd, self.rst):
            assert endpoint.wait_for_subscribers(1, 20.0), 'node not found'
        for endpoint in (self.res, self.img):
            assert endpoint.wait_for_publishers(1, 20.0), 'node not found'

    def _wait(self, step_id: int, reset_id: int | None) -> None:
        got_result = got_image = False
        deadline = time.monotonic() + TIMEOUT_S
        while not (got_result and got_image):
            if time.monotonic() > deadline:
                raise TimeoutError(f'no answer to step_id {step_id}')
            if not got_result:
                self.res.wait(0.5)
                for _, msg in self.res.take():
                    got_result |= msg.step_id == step_id and (
                        reset_id is None or msg.reset_id == reset_id)
            if got_result and not got_image:
                self.img.wait(0.5)
            # The image is published before the result; take whatever is there.
            got_image |= bool(self.img.take()) or (got_image and got_result)

    def step(self, step_id: int, action: int) -> None:
        self.cmd.publish(self.types.new(self.types.LIGHT_COMMAND, step_id=step_id, mode=2,
                                        action=action))
        self._wait(step_id, None)

    def reset(self, reset_id: int) -> None:
        self.rst.publish(self.types.new(self.types.RESET_REQUEST, reset_id=reset_id))
        self._wait(0, reset_id)


def over_dds(episodes: int, repeats: int, seed: int) -> list[float]:
    from growspace_sim.node.interface import COMMAND_QOS, OBSERVATION_QOS
    from growspace_sim.ros import dds

    node = subprocess.Popen([sys.executable, '-m', 'growspace_sim.node.main', '--ros-args',
                             '-r', '__ns:=/bench', '-p', f'seed:={seed}'],
                            stderr=subprocess.DEVNULL)
    rates = []
    try:
        with dds.DdsContext('bench_client', '/bench') as ctx:
            client = Client(ctx, COMMAND_QOS, OBSERVATION_QOS)
            rng = np.random.default_rng(seed)
            reset_id = 0
            for _ in range(repeats):
                start = time.perf_counter()
                for _ in range(episodes):
                    reset_id += 1
                    client.reset(reset_id)
                    for step_id in range(1, EPISODE + 1):
                        client.step(step_id, int(rng.integers(5)))
                rates.append(episodes * EPISODE / (time.perf_counter() - start))
    finally:
        node.terminate()
        try:
            node.wait(10)
        except subprocess.TimeoutExpired:
            node.kill()
            node.wait()
    return rates


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n', 1)[0])
    parser.add_argument('--episodes', type=int, default=20)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args()
    os.environ.setdefault('CYCLONEDDS_URI', (ROOT / 'config' / 'cyclonedds.xml').as_uri())
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(100, 200)))
    os.environ['GROWSPACE_TRANSPORT'] = 'dds'
    local = [in_process(args.episodes, args.seed) for _ in range(args.repeats)]
    remote = over_dds(args.episodes, args.repeats, args.seed)
    best_local, best_remote = max(local), max(remote)
    print(f'{"path":<34}{"steps/s (best)":>16}{"all runs":>30}')
    print(f'{"in-process gymnasium env":<34}{best_local:>16.0f}'
          f'{" ".join(f"{r:.0f}" for r in local):>30}')
    print(f'{"sim_node lockstep over DDS":<34}{best_remote:>16.0f}'
          f'{" ".join(f"{r:.0f}" for r in remote):>30}')
    print(f'ratio node / in-process: {best_remote / best_local:.0%} '
          f'(targets: >= 50% and >= 2000 steps/s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
