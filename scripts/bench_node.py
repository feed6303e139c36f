#!/usr/bin/env python3
"""Lockstep round trip through the rclpy sim_node vs the in-process env, same run.

Method: control easy, discrete random actions (seeded), 50-step episodes. The node is the
installed ``sim_node`` in a child process (lockstep, random domain, loopback only); the client
(an ``RclpyTransport``, as the bridge uses) sends a LightCommand
and waits for both its StepResult and its Image before the next one; episodes end with a reset
that is waited for too. The in-process figure is ``gymnasium.make('GrowSpace/Control-Easy-v0')``
stepping the same way (obs + reward). Steps/s counts steps only, reset time included. Each
figure is the best of ``--repeats`` runs of ``--episodes`` episodes; CPU per step of the node
(from /proc) and of the client (process time) is over all repeats.

Usage (workspace sourced, e.g. inside ``./run.sh`` or after ``source install/setup.bash``):
    python scripts/bench_node.py [--episodes 20] [--repeats 3]
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

from bench_common import cpu_seconds

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
    """Lockstep client: waits for the StepResult and the Image of every request."""

    def __init__(self) -> None:
        from growspace_sim.ros.interface import COMMAND_QOS, OBSERVATION_QOS
        from growspace_sim.node.rclpy_transport import RclpyTransport
        from growspace_sim.ros import types

        self.types = types
        self.transport = t = RclpyTransport('bench_client', '/bench')
        self.cmd = t.publisher(types.LIGHT_COMMAND, 'light/command', COMMAND_QOS)
        self.rst = t.publisher(types.RESET_REQUEST, 'reset', COMMAND_QOS)
        self.result: object = None
        self.images = 0
        t.subscribe(types.STEP_RESULT, 'step_result', OBSERVATION_QOS,
                    lambda msg, _: setattr(self, 'result', msg))
        t.subscribe(types.IMAGE, 'camera/image_raw', OBSERVATION_QOS, self._image)
        deadline = time.monotonic() + 20.0
        topics = ('light/command', 'reset', 'step_result', 'camera/image_raw')
        while not all(map(t.matched, topics)):
            assert time.monotonic() < deadline, 'node not found'
            t.spin_once(0.05)
        end = time.monotonic() + 0.3
        while time.monotonic() < end:
            t.spin_once(0.05)
        self.command = types.new(types.LIGHT_COMMAND, mode=2)

    def _image(self, msg: object, _: bytes) -> None:
        self.images += 1

    def _wait(self, step_id: int, reset_id: int | None) -> None:
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            r = self.result
            if r is not None and r.step_id == step_id and (
                    reset_id is None or r.reset_id == reset_id) and self.images:
                break  # the image is published before the result
            if time.monotonic() > deadline:
                raise TimeoutError(f'no answer to step_id {step_id}')
            self.transport.spin_once(0.5)
        self.result, self.images = None, 0

    def step(self, step_id: int, action: int) -> None:
        self.command.step_id, self.command.action = step_id, action
        self.cmd(self.command)
        self._wait(step_id, None)

    def reset(self, reset_id: int) -> None:
        self.rst(self.types.new(self.types.RESET_REQUEST, reset_id=reset_id))
        self._wait(0, reset_id)


def over_ros(episodes: int, repeats: int, seed: int) -> tuple[list[float], float, float]:
    """Steps/s of each repeat, and node and client CPU per step [s]."""
    from growspace_sim.node.main import installed_executable

    node = subprocess.Popen([installed_executable(), '--ros-args', '-r', '__ns:=/bench',
                             '-p', f'seed:={seed}'], stderr=subprocess.DEVNULL)
    rates = []
    try:
        client = Client()
        rng = np.random.default_rng(seed)
        reset_id = 0
        node_cpu, client_cpu = cpu_seconds(node.pid), time.process_time()
        for _ in range(repeats):
            start = time.perf_counter()
            for _ in range(episodes):
                reset_id += 1
                client.reset(reset_id)
                for step_id in range(1, EPISODE + 1):
                    client.step(step_id, int(rng.integers(5)))
            rates.append(episodes * EPISODE / (time.perf_counter() - start))
        steps = repeats * episodes * EPISODE
        node_cpu = (cpu_seconds(node.pid) - node_cpu) / steps
        client_cpu = (time.process_time() - client_cpu) / steps
        client.transport.close()
    finally:
        node.terminate()
        try:
            node.wait(10)
        except subprocess.TimeoutExpired:
            node.kill()
            node.wait()
    return rates, node_cpu, client_cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n', 1)[0])
    parser.add_argument('--episodes', type=int, default=20)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args()
    from growspace_sim.ros import loopback

    loopback.confine()
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(1, 101)))
    local = [in_process(args.episodes, args.seed) for _ in range(args.repeats)]
    remote, node_cpu, client_cpu = over_ros(args.episodes, args.repeats, args.seed)
    best_local, best_remote = max(local), max(remote)
    print(f'{"path":<34}{"steps/s (best)":>16}{"all runs":>30}')
    print(f'{"in-process gymnasium env":<34}{best_local:>16.0f}'
          f'{" ".join(f"{r:.0f}" for r in local):>30}')
    print(f'{"sim_node lockstep over rclpy":<34}{best_remote:>16.0f}'
          f'{" ".join(f"{r:.0f}" for r in remote):>30}')
    print(f'ratio node / in-process: {best_remote / best_local:.0%} (target: >= 1,500 steps/s)')
    print(f'CPU per step: node {node_cpu * 1e6:.0f} us, client {client_cpu * 1e6:.0f} us')
    return 0


if __name__ == '__main__':
    sys.exit(main())
