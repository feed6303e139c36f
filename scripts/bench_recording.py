#!/usr/bin/env python3
"""Recording overhead: lockstep steps/s with and without the MCAP recorder, in one run.

Three variants run the same seeded episodes with the same pre-drawn random actions, alternating
over several rounds (the best round of each counts, which filters scheduler noise):
- ``sim``: Simulation only (apply action, step, render); the floor;
- ``node``: EpisodeRunner without a recorder: also builds and serialises every message the node
  publishes, i.e. the node's cost without recording;
- ``record``: the same plus ``McapRecorder`` writing zstd chunks to a file.
Overhead = node / record - 1 (target <= 10 %), in wall time and in CPU time of the stepping
thread (the recorder compresses and writes on a worker thread, which on a loaded machine competes
for the same cores; thread CPU time is what the node's own loop pays). Bytes per step = file size
/ steps.

Usage: PYTHONPATH=src/growspace_sim python scripts/bench_recording.py [--challenge control]
       [--episodes 20] [--rounds 5] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

from growspace_sim.core.config import CHALLENGES, SimConfig
from growspace_sim.episode_runner import EpisodeRunner
from growspace_sim.recording import McapRecorder
from growspace_sim.simulation import Simulation


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


def run_runner(cfg: SimConfig, plan: np.ndarray, recorder: McapRecorder | None) -> int:
    runner = EpisodeRunner(cfg, recorder)
    steps = 0
    for episode, row in enumerate(plan):
        runner.reset(episode, request=episode > 0)
        for action in row:
            runner.step(int(action))
            steps += 1
    return steps


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--challenge', choices=CHALLENGES, default='control')
    parser.add_argument('--episodes', type=int, default=20)
    parser.add_argument('--rounds', type=int, default=5)
    parser.add_argument('--json', type=Path, help='also write the results here')
    args = parser.parse_args()
    cfg = SimConfig(challenge=args.challenge)
    plan = actions(cfg, args.episodes)
    best = {'sim': 0.0, 'node': 0.0, 'record': 0.0}
    best_cpu = dict(best)
    size = steps = 0
    with tempfile.TemporaryDirectory() as tmp:
        run_runner(cfg, plan[:1], None)  # warm caches (digits, typestore)
        for i in range(args.rounds):
            for variant in best:
                path = Path(tmp) / f'bench{i}.mcap'
                start, start_cpu = time.perf_counter(), time.thread_time()
                if variant == 'sim':
                    steps = run_sim(cfg, plan)
                elif variant == 'node':
                    steps = run_runner(cfg, plan, None)
                else:
                    with McapRecorder(path) as recorder:
                        steps = run_runner(cfg, plan, recorder)
                rate = steps / (time.perf_counter() - start)
                best[variant] = max(best[variant], rate)
                best_cpu[variant] = max(best_cpu[variant],
                                        steps / (time.thread_time() - start_cpu))
                if variant == 'record':
                    size = path.stat().st_size
    result = {
        'challenge': args.challenge, 'steps': steps, 'rounds': args.rounds,
        'steps_per_s': {k: round(v, 1) for k, v in best.items()},
        'thread_cpu_steps_per_s': {k: round(v, 1) for k, v in best_cpu.items()},
        'recording_overhead': round(best['node'] / best['record'] - 1.0, 4),
        'recording_overhead_thread_cpu': round(best_cpu['node'] / best_cpu['record'] - 1.0, 4),
        'bytes_per_step': round(size / steps, 1),
        'raw_image_bytes_per_step': cfg.resolution ** 2 * 3,
    }
    print(f'{args.challenge}: {steps} steps x {args.rounds} rounds (best round)')
    for k, v in best.items():
        print(f'  {k:>6}: {v:8.1f} steps/s wall, {best_cpu[k]:8.1f} steps/s of thread CPU')
    print(f'  recording overhead vs node: {result["recording_overhead"]:+.1%} wall, '
          f'{result["recording_overhead_thread_cpu"]:+.1%} stepping-thread CPU '
          f'(target <= +10%)')
    print(f'  file: {result["bytes_per_step"]:.0f} B/step '
          f'(raw image alone {result["raw_image_bytes_per_step"]} B)')
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
