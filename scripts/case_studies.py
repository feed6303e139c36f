#!/usr/bin/env python3
"""The paper's case studies with PPO, plus A2C / DQN / Rainbow on control easy, in one command.

Trains every run in parallel (one process each, one torch thread each), then evaluates all
policies against the random agent and the oracle on the same seeds, and writes the table and
figures. Each training run has the same wall-clock budget (``--minutes``) and stops early at
``--steps``; run.json records the steps it reached.

    python scripts/case_studies.py --minutes 6 --device cuda --out runs/case_studies \
        --docs docs          # what produced docs/baselines.md (see there for the machine)
    python scripts/case_studies.py --minutes 0.2 --seeds 1 --episodes 3 --out /tmp/cs   # smoke

Needs the learn extra (requirements-learn.txt).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / 'src' / 'growspace_sim'))

from growspace_sim.learn import evaluate_policies  # noqa: E402

CASES = ['Control-Easy', 'Control-Hard', 'FindPlant-Easy', 'FindPlant-Hard', 'Fairness-Easy',
         'Fairness-Hard', 'Shape-Easy', 'Shape-Hard', 'Shape-Curriculum', 'Shape-AllDigits']
BASELINE_ALGOS = ['a2c', 'dqn', 'rainbow']
# PPO for the case studies: the paper's values, except the rollout (8 envs x 256 steps = 2048
# per update instead of 2500) and the minibatch, read as the paper's code base reads
# "mini batch 32": 32 minibatches per epoch (of 64 samples), not minibatches of 32 samples.
CASE_PPO = ['n_steps=256', 'batch_size=64']
CASE_PPO_ENVS = 8
BEGIN, END = '<!-- case-studies:begin -->', '<!-- case-studies:end -->'


def train_commands(args: argparse.Namespace) -> list[tuple[str, list[str]]]:
    """(run dir, growspace-train argv) for every run."""
    common = ['--steps', str(args.steps), '--max-minutes', str(args.minutes), '--device',
              args.device, '--no-progress-bar', '--checkpoint-every', str(args.steps)]
    episodes_per_stage = max(1, args.expected_steps // CASE_PPO_ENVS // 50 // 12)
    runs = []
    for case in args.cases.split(','):
        for seed in range(args.seeds if case != 'Control-Easy' else max(args.seeds, 3)):
            out = str(Path(args.out) / f'ppo-{case.lower()}-s{seed}')
            argv = ['--algo', 'ppo', '--env', f'GrowSpace/{case}-v0', '--seed', str(seed),
                    '--out', out, '--n-envs', str(CASE_PPO_ENVS), *common]
            for hp in CASE_PPO:
                argv += ['--hp', hp]
            if case == 'Shape-Curriculum':
                argv += ['--env-kwargs', json.dumps({'episodes_per_stage': episodes_per_stage})]
            runs.append((out, argv))
    for algo in BASELINE_ALGOS if args.baselines else []:
        out = str(Path(args.out) / f'{algo}-control-easy-s0')
        runs.append((out, ['--algo', algo, '--env', 'GrowSpace/Control-Easy-v0', '--seed', '0',
                           '--out', out, *common]))
    return runs


def run_all(runs: list[tuple[str, list[str]]], log_dir: Path) -> float:
    """Start every training at once; returns the wall time."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(ROOT / 'src' / 'growspace_sim'),
                                                      env.get('PYTHONPATH')]))
    env.setdefault('OMP_NUM_THREADS', '1')
    log_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    procs = []
    for out, argv in runs:
        log = open(log_dir / f'{Path(out).name}.log', 'w')
        procs.append((out, log, subprocess.Popen(
            [sys.executable, '-m', 'growspace_sim.learn.train', *argv], stdout=log,
            stderr=subprocess.STDOUT, env=env)))
    for out, log, proc in procs:
        if proc.wait() != 0:
            print(f'training {out} failed (exit {proc.returncode}); see its log', file=sys.stderr)
        log.close()
    return time.perf_counter() - start


def budget_note(runs: list[str], train_wall: float, eval_wall: float,
                args: argparse.Namespace) -> str:
    infos = [json.loads((Path(r) / 'run.json').read_text()) for r in runs]
    steps = {}
    for info in infos:
        steps.setdefault(info['algo'], []).append(info['steps'])
    spread = ', '.join(f'{algo} {min(s):,}-{max(s):,} steps' for algo, s in steps.items())
    return (f'Budget: {args.minutes:g} min of wall time per training run (cap {args.steps:,} '
            f'steps), {len(runs)} runs at once on `{args.machine}`, device `{args.device}`, '
            f'one torch thread each; steps reached: {spread}. Training took '
            f'{train_wall / 60:.1f} min, '
            f'evaluation ({args.episodes} episodes per agent and run, seeds '
            f'{args.eval_seed}..{args.eval_seed + args.episodes - 1}) {eval_wall / 60:.1f} min.')


def write_docs(docs: Path, out: Path, note: str, table: str) -> None:
    figures = docs / 'figures'
    figures.mkdir(parents=True, exist_ok=True)
    for name in ('rewards', 'training'):
        shutil.copy(out / 'eval' / f'{name}.png', figures / f'baselines_{name}.png')
    block = (f'{BEGIN}\n{note}\n\n{table}\n\n'
             '![cumulative reward per case](figures/baselines_rewards.png)\n\n'
             '![training curves](figures/baselines_training.png)\n' + END)
    path = docs / 'baselines.md'
    text = path.read_text() if path.exists() else f'# Learned baselines\n\n{BEGIN}\n{END}\n'
    if BEGIN not in text:
        text += f'\n{BEGIN}\n{END}\n'
    path.write_text(re.sub(re.escape(BEGIN) + '.*?' + re.escape(END), lambda _: block, text,
                           flags=re.S))


def assemble(args: argparse.Namespace) -> int:
    """Merge eval folders of several calls (e.g. one per machine lease) into the docs block."""
    out = Path(args.out)
    by_key, curves, notes = {}, {}, []
    for eval_dir in args.assemble:  # a later call's (env, agent) replaces an earlier one's
        more_rows, more_curves = evaluate_policies.load_results(eval_dir)
        by_key.update({(r.env, r.agent): r for r in more_rows})
        for env_id, labels in more_curves.items():
            curves.setdefault(env_id, {}).update(labels)
        notes.append((Path(eval_dir) / 'results.md').read_text().split('\n\n')[0])
    rows = sort_rows(list(by_key.values()))
    merged = out / 'eval'
    merged.mkdir(parents=True, exist_ok=True)
    evaluate_policies.write_csv(rows, merged / 'results.csv')
    evaluate_policies.plot_rewards(curves, merged / 'rewards.png')
    groups: dict[str, list[str]] = {}
    for run_json in sorted(out.glob('*/run.json')):
        case = evaluate_policies.case_name(evaluate_policies.eval_env_of(str(run_json.parent)))
        groups.setdefault(case, []).append(str(run_json.parent))
    order = case_order()
    groups = dict(sorted(groups.items(), key=lambda item: order.get(item[0], 99)))
    evaluate_policies.plot_training(groups, merged / 'training.png')
    table = evaluate_policies.markdown(rows)
    note = '\n\n'.join(f'Call {i + 1}: {n}' for i, n in enumerate(notes))
    (merged / 'results.md').write_text(f'{note}\n\n{table}\n')
    print(f'{note}\n\n{table}')
    if args.docs:
        write_docs(Path(args.docs), out, note, table)
    return 0


def case_order() -> dict[str, int]:
    return {evaluate_policies.case_name(f'GrowSpace/{c}-v0'): i for i, c in enumerate(CASES)}


def sort_rows(rows: list) -> list:
    order = case_order()
    agents = {'random': 0, 'oracle': 1}
    return sorted(rows, key=lambda r: (order.get(r.case, 99), agents.get(r.agent, 2), r.agent))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--minutes', type=float, default=6.0, help='wall time per training run')
    parser.add_argument('--steps', type=int, default=1_000_000, help='step cap per run')
    parser.add_argument('--expected-steps', type=int, default=60_000,
                        help='steps a curriculum run is expected to reach (sets its stage length)')
    parser.add_argument('--seeds', type=int, default=2,
                        help='PPO seeds per case (at least 3 for control easy)')
    parser.add_argument('--cases', default=','.join(CASES), help='comma-separated subset')
    parser.add_argument('--no-baselines', dest='baselines', action='store_false',
                        help='skip A2C / DQN / Rainbow on control easy')
    parser.add_argument('--device', default='cpu')
    parser.add_argument('--episodes', type=int, default=60, help='eval episodes per agent and run')
    parser.add_argument('--eval-seed', type=int, default=10_000)
    parser.add_argument('--workers', type=int, default=os.cpu_count() or 1)
    parser.add_argument('--out', default='runs/case_studies')
    parser.add_argument('--docs', help='also write DOCS/baselines.md (block) and DOCS/figures/')
    parser.add_argument('--machine', default=f'{os.cpu_count()} CPU cores',
                        help='described in the budget note')
    parser.add_argument('--skip-train', action='store_true', help='evaluate existing runs only')
    parser.add_argument('--assemble', nargs='+', metavar='EVAL_DIR',
                        help='no training or evaluation: merge the results of earlier calls '
                             '(their eval/ folders; runs under --out) into one table and figures')
    args = parser.parse_args(argv)
    out = Path(args.out)
    if args.assemble:
        return assemble(args)
    runs = train_commands(args)
    train_wall = 0.0
    if not args.skip_train:
        train_wall = run_all(runs, out / 'logs')
    done = [r for r, _ in runs if (Path(r) / 'run.json').exists()]
    start = time.perf_counter()
    rows = evaluate_policies.compare(done, args.episodes, out / 'eval', args.eval_seed,
                                     min(args.workers, 16))
    eval_wall = time.perf_counter() - start
    rows = sort_rows(rows)
    table = evaluate_policies.markdown(rows)
    note = budget_note(done, train_wall, eval_wall, args)
    (out / 'eval' / 'results.md').write_text(f'{note}\n\n{table}\n')
    print(f'{note}\n\n{table}')
    if args.docs:
        write_docs(Path(args.docs), out, note, table)
    return 0 if len(done) == len(runs) else 1


if __name__ == '__main__':
    sys.exit(main())
