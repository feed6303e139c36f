#!/usr/bin/env python3
"""Wall time of a fixed growspace-sweep with 1 and 2 trials at once, and Ray's cost per trial.

One local Ray instance (bound to 127.0.0.1, as growspace-sweep starts it) with --cpus CPUs,
warmed up by a one-trial sweep (Tune's first run in a process pays its imports); every sweep
starts from an empty folder. For each sweep: the wall time of the Tune run (Ray's
start-up is timed once, apart), the work the trials did (the sum of their own wall_s, measured
inside the trial) and Ray's overhead per trial = (wall x concurrency - work) / trials, the
time a trial slot is busy with something other than the trial's work. The sequential row runs
the same trials with growspace_sim.sweep.run_trial in this process, without Ray.

    python scripts/bench_sweep.py --trials 16 --episodes 20          # evaluation trials
    python scripts/bench_sweep.py --trials 4 --agent ppo --steps 2048  # tiny PPO trials (torch)
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import growspace_sim  # noqa: F401
from growspace_sim import sweep


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--agent', default='random')
    parser.add_argument('--env', default='GrowSpace/Control-Easy-v0')
    parser.add_argument('--trials', type=int, default=16, help='seeds 0..n-1')
    parser.add_argument('--episodes', type=int, default=20)
    parser.add_argument('--steps', type=int, default=2048, help='learners only')
    parser.add_argument('--workers', default='1,2', help='concurrency levels to time')
    parser.add_argument('--cpus', type=int, default=2)
    parser.add_argument('--fresh-processes', action='store_true',
                        help='a new worker process per trial (no reuse_actors)')
    parser.add_argument('--json', help='also write the figures here')
    args = parser.parse_args()
    group = {'agents': [args.agent], 'envs': [args.env], 'seeds': args.trials}
    if args.agent in sweep.LEARNERS:
        group.update(steps=args.steps, n_envs=2, hp={'n_steps': 256, 'batch_size': 64})
    spec = sweep.parse_spec({'name': 'bench', 'episodes': args.episodes, 'eval_seed': 0,
                             'runs': [group]})
    rows = []
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        work = 0.0
        for i, trial in enumerate(spec.trials):
            out = Path(tmp) / f'seq{i}'
            out.mkdir()
            work += sweep.run_trial(trial, out)['wall_s']
        rows.append(dict(mode='sequential, no Ray', workers=1,
                         wall_s=time.perf_counter() - start, work_s=work, overhead_s=0.0))
        start = time.perf_counter()
        sweep.connect(None, args.cpus)
        startup = time.perf_counter() - start
        try:
            warm = sweep.Spec('warm-up', spec.episodes, 0, spec.trials[:1])
            start = time.perf_counter()
            sweep.run_sweep(warm, Path(tmp) / 'warm-up', workers=1, verbose=0)
            first = time.perf_counter() - start
            for workers in map(int, args.workers.split(',')):
                start = time.perf_counter()
                outcomes = sweep.run_sweep(spec, Path(tmp) / f'w{workers}', workers=workers,
                                           verbose=0,
                                           reuse_actors=not args.fresh_processes)
                wall = time.perf_counter() - start
                assert len(outcomes) == len(spec.trials) and not any(o.error for o in outcomes)
                work = sum(o.summary['wall_s'] for o in outcomes)
                rows.append(dict(mode='Ray Tune', workers=workers, wall_s=wall, work_s=work,
                                 overhead_s=(wall * workers - work) / len(outcomes)))
        finally:
            sweep.disconnect()  # every Ray process, agents included, before the figures
    print(f'{len(spec.trials)} trials of {args.agent} on {args.env} '
          f'({args.episodes} evaluation episodes'
          + (f', {args.steps} training steps' if args.agent in sweep.LEARNERS else '')
          + f'); Ray start-up {startup:.1f} s, a first one-trial sweep (not timed below) '
          f'{first:.1f} s; fresh processes: {args.fresh_processes}\n')
    print(f'load average before / after: {load[0]:.1f} / {os.getloadavg()[0]:.1f}\n')
    print('| mode | trials at once | wall s | trial work s | Ray overhead per trial s |')
    print('|---|---|---|---|---|')
    for r in rows:
        print(f'| {r["mode"]} | {r["workers"]} | {r["wall_s"]:.1f} | {r["work_s"]:.1f} '
              f'| {r["overhead_s"]:.2f} |')
    if args.json:
        figures = dict(startup_s=startup, first_sweep_s=first, load=load, rows=rows)
        Path(args.json).write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
