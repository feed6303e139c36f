#!/usr/bin/env python3
"""Recording overhead: lockstep steps/s with and without the MCAP recorder, in one run.

Three variants run the same seeded episodes with the same pre-drawn random actions, alternating
round by round; each variant's best round counts (a shared VM's noise only ever slows a round
down, so the fastest round is the closest to the true cost):
- ``sim``: Simulation only (apply action, step, render); the floor;
- ``node``: EpisodeRunner without a recorder: the ChamberNode in process, building and
  serialising every message it publishes, i.e. the node's cost without recording;
- ``record``: the same plus ``McapRecorder`` writing zstd chunks to a file;
- ``mcap``: the same with mcap's own ``Writer`` (zstd chunks of the same size) behind the same
  recorder interface: what our chunk writer (``recording/chunk_writer.py``) must beat to stay.
Overhead = node / record - 1 (issue 17's target: <= 15 %), in wall time and in CPU time of the
whole process (the recorder compresses and writes on a worker thread; on 2 cores that thread
competes with the chamber, so process CPU is the honest measure of what recording costs); also
as microseconds of process CPU each layer adds to a step. Bytes per step = file size / steps.

Usage (workspace sourced): python scripts/bench_recording.py [--challenge control]
       [--episodes 8] [--rounds 15] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

from growspace_sim.core import task as tasks
from growspace_sim.core.config import SimConfig
from growspace_sim.node.episode_runner import EpisodeRunner
from growspace_sim.recording import CHUNK_SIZE, McapRecorder, PROFILE
from growspace_sim.ros import qos as ros_qos, types
from growspace_sim.simulation import Simulation

VARIANTS = ('sim', 'node', 'record', 'mcap')


class LibraryRecorder:
    """The node's recorder interface on mcap's own ``Writer``, for comparison only (no crash
    safety, no background thread: what a plain use of the library gives)."""

    error = None

    def __init__(self, path: Path) -> None:
        from mcap.writer import CompressionType, Writer

        self._file = open(path, 'wb')
        self._writer = Writer(self._file, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library='bench')
        self._schemas: dict[str, int] = {}

    def add_channel(self, topic: str, typename: str, qos: ros_qos.QosProfile) -> int:
        if typename not in self._schemas:
            self._schemas[typename] = self._writer.register_schema(
                typename, 'ros2msg', types.msgdef(typename).encode())
        return self._writer.register_channel(topic, 'cdr', self._schemas[typename], {
            'offered_qos_profiles': ros_qos.offered_qos_yaml(qos),
            'topic_type_hash': types.type_hash(typename)})

    def write_many(self, messages: list[tuple[int, bytes, int, int]]) -> None:
        for channel, data, log_time, publish_time in messages:
            self._writer.add_message(channel, log_time, data, publish_time)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name, data)

    def close(self) -> None:
        self._writer.finish()
        self._file.close()


def actions(cfg: SimConfig, episodes: int) -> np.ndarray:
    n = 7 if cfg.uses_spotlight else 5
    return np.random.default_rng(0).integers(0, n, (episodes, cfg.episode_length))


def run_sim(cfg: SimConfig, plan: np.ndarray) -> int:
    sim = Simulation(cfg)
    steps = 0
    for episode, row in enumerate(plan):
        sim.reset(seed=episode)
        sim.observe()
        for action in row:
            sim.apply_discrete(int(action))
            sim.step()
            sim.observe()
            steps += 1
    return steps


def run_runner(cfg: SimConfig, plan: np.ndarray, recorder: object | None) -> int:
    runner = EpisodeRunner(cfg, recorder)
    steps = 0
    for episode, row in enumerate(plan):
        runner.reset(seed=episode)
        for action in row:
            runner.step(int(action))
            steps += 1
    return steps


def run(variant: str, cfg: SimConfig, plan: np.ndarray, path: Path) -> int:
    if variant == 'sim':
        return run_sim(cfg, plan)
    if variant == 'node':
        return run_runner(cfg, plan, None)
    if variant == 'mcap':
        recorder = LibraryRecorder(path)
        try:
            return run_runner(cfg, plan, recorder)
        finally:
            recorder.close()  # timed too, as our recorder's close below
    with McapRecorder(path) as recorder:  # closing (the last chunk, the summary) is timed too
        return run_runner(cfg, plan, recorder)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--challenge', choices=tasks.names(), default='control')
    parser.add_argument('--episodes', type=int, default=8)
    parser.add_argument('--rounds', type=int, default=15)
    parser.add_argument('--json', type=Path, help='also write the results here')
    args = parser.parse_args()
    cfg = SimConfig(challenge=args.challenge)
    plan = actions(cfg, args.episodes)
    wall = {v: 0.0 for v in VARIANTS}  # best steps/s
    cpu = dict(wall)
    size = steps = 0
    with tempfile.TemporaryDirectory() as tmp:
        run_runner(cfg, plan[:1], None)  # warm caches (digits, typestore)
        for i in range(args.rounds):
            for variant in VARIANTS:
                path = Path(tmp) / f'bench{i}.mcap'
                start, start_cpu = time.perf_counter(), time.process_time()
                steps = run(variant, cfg, plan, path)
                wall[variant] = max(wall[variant], steps / (time.perf_counter() - start))
                cpu[variant] = max(cpu[variant], steps / (time.process_time() - start_cpu))
                if variant == 'record':
                    size = path.stat().st_size
                path.unlink(missing_ok=True)
    result = {
        'challenge': args.challenge, 'steps': steps, 'rounds': args.rounds,
        'steps_per_s': {k: round(v, 1) for k, v in wall.items()},
        'process_cpu_steps_per_s': {k: round(v, 1) for k, v in cpu.items()},
        'recording_overhead': round(wall['node'] / wall['record'] - 1.0, 4),
        'recording_overhead_process_cpu': round(cpu['node'] / cpu['record'] - 1.0, 4),
        'mcap_writer_overhead_process_cpu': round(cpu['node'] / cpu['mcap'] - 1.0, 4),
        # What each layer adds per step, in us of process CPU: absolute, unlike the ratios.
        'node_us_per_step': round(1e6 / cpu['node'] - 1e6 / cpu['sim'], 1),
        'recording_us_per_step': round(1e6 / cpu['record'] - 1e6 / cpu['node'], 1),
        'bytes_per_step': round(size / steps, 1),
        'raw_image_bytes_per_step': cfg.resolution ** 2 * 3,
    }
    print(f'{args.challenge}: {steps} steps x {args.rounds} rounds (best round)')
    for k in VARIANTS:
        print(f'  {k:>6}: {wall[k]:8.1f} steps/s wall, {cpu[k]:8.1f} steps/s of process CPU')
    print(f'  recording overhead vs node: {result["recording_overhead"]:+.1%} wall, '
          f'{result["recording_overhead_process_cpu"]:+.1%} process CPU (target <= +15%)')
    print(f'  per step: the node adds {result["node_us_per_step"]} us to the sim, recording '
          f'{result["recording_us_per_step"]} us to the node (process CPU)')
    print(f'  mcap\'s own Writer instead: {result["mcap_writer_overhead_process_cpu"]:+.1%} '
          f'process CPU')
    print(f'  file: {result["bytes_per_step"]:.0f} B/step '
          f'(raw image alone {result["raw_image_bytes_per_step"]} B)')
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
