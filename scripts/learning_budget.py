#!/usr/bin/env python3
"""The paper's learning budget on whatever machine this runs on: profile, train, resume.

Three commands (needs the learn extra, requirements-learn.txt):

``profile``: where one PPO update of the case studies' settings goes (2,048 steps: 8 envs x
256, 4 epochs of minibatches of 64), per configuration: the vector env, the rollout buffer,
the number of envs (``n_envs`` x ``n_steps`` stays 2,048), the device. Each configuration
trains one warm-up update, then ``--updates`` timed updates with every part wrapped in a
timer (on CUDA each timer synchronises first, so each part is charged with its own GPU work);
prints one table and writes JSON::

    python scripts/learning_budget.py profile --device cpu --updates 1 --json /tmp/profile.json

``train``: the eight cases (and the curriculum) x seeds with PPO to ``--steps`` in parallel
processes (one torch thread each), each stopping after ``--minutes`` of wall time and resumed
by the next call of the same command from its run folder (``growspace-train --resume``):

    python scripts/learning_budget.py train --out runs/budget --steps 1000000 --minutes 60 \\
        --device cuda --seeds 3 --vec native --rollout-buffer device

Repeat it until every run reports its steps. It prints one line per run (steps reached,
steps/s of this call) and the call's total. ``--export DIR`` then copies each run's small
files (run.json, episodes.csv, progress*.csv) into one ``runs.tar.gz`` and each challenge's
best policy (highest mean return over the last 100 training episodes; the weights alone, a
torch state dict) into ``DIR``, so that they fit the few files a lent machine hands back;
the checkpoints (weights + Adam state, ~19 MB a run) stay in ``--out``.

``report``: issue 32's summary line (``learning: runs=.. steps_per_run=.. ppo_beats_random=..
ppo_within_oracle_10pct=.. camera_ratio_min=.. hours_total=..``) from ``growspace-compare``'s
results.csv, the camera loop's JSON and the train calls' call_*.json.

``camera``: the policies ``export`` wrote, run closed loop on the twin rig, each step's
observation drawn from the camera pipeline's measurement of a twin photo (as
``scripts/bench_camera.py``'s closed loop), against the same policy on the simulator's own
observation, on the same episode seeds; camera return / simulator return per challenge.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import time
from collections import defaultdict
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
for package in ('growspace_sim', 'growspace_camera'):
    sys.path.insert(0, str(ROOT / 'src' / package))

import numpy as np  # noqa: E402

CASES = ('Control-Easy', 'Control-Hard', 'FindPlant-Easy', 'FindPlant-Hard', 'Fairness-Easy',
         'Fairness-Hard', 'Shape-Easy', 'Shape-Hard')
EXTRA_CASES = ('Shape-Curriculum', 'Shape-AllDigits')  # the MNIST curriculum study
# The case studies' PPO (docs/baselines.md): the paper's values with 2,048 steps per update
# and minibatches of 64 (32 per epoch).
ROLLOUT = 2048
CASE_HP = {'batch_size': 64}
EPISODE_STEPS = 50
CURRICULUM_STAGES = 12  # 10 digits join over the first stages; the last ones train on all


# ---------------------------------------------------------------- profile

class Timers:
    """Seconds per named part; ``wrap`` replaces a bound method by a timed one."""

    def __init__(self, sync) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self.sync = sync

    @contextmanager
    def part(self, name: str):
        self.sync()
        start = time.perf_counter()
        try:
            yield
        finally:
            self.sync()
            self.seconds[name] += time.perf_counter() - start
            self.calls[name] += 1

    def wrap(self, owner, method: str, name: str) -> None:
        inner = getattr(owner, method)

        def timed(*args, **kwargs):
            with self.part(name):
                return inner(*args, **kwargs)
        setattr(owner, method, timed)

    def wrap_generator(self, owner, method: str, name: str) -> None:
        """Time each ``next`` of the generator a method returns (the minibatch fetches)."""
        inner = getattr(owner, method)

        def timed(*args, **kwargs):
            iterator = inner(*args, **kwargs)
            while True:
                with self.part(name):
                    item = next(iterator, StopIteration)
                if item is StopIteration:
                    return
                yield item
        setattr(owner, method, timed)

    def reset(self) -> None:
        self.seconds.clear()
        self.calls.clear()


def profile_one(env_id: str, n_envs: int, vec: str, buffer: str, device: str, updates: int,
                seed: int = 0) -> dict:
    """One warm-up and ``updates`` timed PPO updates; seconds per update and part."""
    import torch  # noqa: PLC0415
    from growspace_sim.learn import train as training  # noqa: PLC0415

    torch.set_num_threads(1)
    env = training.make_env(env_id, n_envs, seed, vec=vec)
    hp = {**CASE_HP, 'n_steps': ROLLOUT // n_envs}
    model = training.build_model('ppo', env, seed, device, hp, rollout_buffer=buffer)
    cuda = model.device.type == 'cuda'
    timers = Timers(torch.cuda.synchronize if cuda else (lambda: None))
    venv = model.get_env()
    timers.wrap(venv, 'step', 'env step (vec env + wrappers)')
    timers.wrap(model.policy, 'forward', 'rollout: policy forward + sample')
    timers.wrap(model.policy, 'predict_values', 'rollout: value of last/terminal obs')
    timers.wrap(model.rollout_buffer, 'add', 'rollout: buffer add')
    timers.wrap(model.rollout_buffer, 'compute_returns_and_advantage', 'GAE')
    timers.wrap_generator(model.rollout_buffer, 'get', 'train: minibatch fetch')
    timers.wrap(model.policy, 'evaluate_actions', 'train: forward (evaluate_actions)')
    timers.wrap(model.policy.optimizer, 'step', 'train: Adam step')
    backward = torch.Tensor.backward

    def timed_backward(self, *args, **kwargs):
        with timers.part('train: backward'):
            return backward(self, *args, **kwargs)
    total_wrapped = {'collect_rollouts': 'rollout (all)', 'train': 'train (all)'}
    for method, name in total_wrapped.items():
        timers.wrap(model, method, name)
    torch.Tensor.backward = timed_backward
    clip = torch.nn.utils.clip_grad_norm_
    timers.wrap(torch.nn.utils, 'clip_grad_norm_', 'train: clip grad norm')
    try:
        model.learn(total_timesteps=ROLLOUT)  # warm-up: allocations, cuDNN autotune, numba
        timers.reset()
        start = time.perf_counter()
        model.learn(total_timesteps=ROLLOUT * updates, reset_num_timesteps=False)
        wall = time.perf_counter() - start
    finally:
        torch.Tensor.backward, torch.nn.utils.clip_grad_norm_ = backward, clip
        env.close()
    parts = {name: s / updates for name, s in timers.seconds.items()}
    inner = ('rollout: policy forward + sample', 'rollout: value of last/terminal obs',
             'rollout: buffer add', 'env step (vec env + wrappers)')
    parts['rollout: other (obs to tensor, callbacks, SB3 loop)'] = (
        parts['rollout (all)'] - sum(parts.get(n, 0.0) for n in inner))
    inner = ('train: minibatch fetch', 'train: forward (evaluate_actions)', 'train: backward',
             'train: clip grad norm', 'train: Adam step')
    parts['train: other (losses, .item() syncs, logging)'] = (
        parts['train (all)'] - sum(parts.get(n, 0.0) for n in inner))
    return dict(env=env_id, n_envs=n_envs, n_steps=ROLLOUT // n_envs, vec=vec, buffer=buffer,
                device=str(model.device), updates=updates, wall_per_update=wall / updates,
                steps_per_s=ROLLOUT / (wall / updates), parts=parts,
                calls={n: c // updates for n, c in timers.calls.items()})


def profile(args: argparse.Namespace) -> int:
    results = []
    for config in args.configs.split(','):
        vec, buffer, n_envs = config.split(':')
        result = profile_one(args.env, int(n_envs), vec, buffer, args.device, args.updates)
        results.append(result)
        print(f'{config} on {result["device"]}: {result["wall_per_update"]:.2f} s per update of '
              f'{ROLLOUT} steps, {result["steps_per_s"]:.0f} steps/s', flush=True)
    names = list(results[0]['parts'])
    head = '| part (s per update) | ' + ' | '.join(
        f'{r["vec"]}, {r["buffer"]} buffer, {r["n_envs"]} envs' for r in results) + ' |'
    lines = [head, '|---' * (len(results) + 1) + '|']
    for name in names:
        lines.append(f'| {name} | ' + ' | '.join(
            f'{r["parts"].get(name, 0.0):.3f}' for r in results) + ' |')
    lines.append('| **update (wall)** | ' + ' | '.join(
        f'**{r["wall_per_update"]:.3f}**' for r in results) + ' |')
    lines.append('| steps/s | ' + ' | '.join(f'{r["steps_per_s"]:.0f}' for r in results) + ' |')
    print('\n'.join(lines))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1) + '\n')
    return 0


# ---------------------------------------------------------------- train

def run_specs(args: argparse.Namespace) -> list[tuple[str, list[str]]]:
    """(run folder, growspace-train argv) of every run of the call."""
    cases = args.cases.split(',')
    n_steps = ROLLOUT // args.n_envs
    runs = []
    for case in cases:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            out = str(Path(args.out) / f'ppo-{case.lower()}-s{seed}')
            argv = ['--algo', 'ppo', '--env', f'GrowSpace/{case}-v0', '--seed', str(seed),
                    '--out', out, '--n-envs', str(args.n_envs), '--vec', args.vec,
                    '--rollout-buffer', args.rollout_buffer, '--steps', str(args.steps),
                    '--max-minutes', str(args.minutes), '--device', args.device,
                    '--no-progress-bar', '--checkpoint-every', str(args.checkpoint_every),
                    '--resume', '--hp', f'n_steps={n_steps}', '--hp',
                    f'batch_size={CASE_HP["batch_size"]}']
            if case == 'Shape-Curriculum':  # the stages spread over the whole budget
                per_stage = max(1, args.steps // args.n_envs // EPISODE_STEPS
                                // CURRICULUM_STAGES)
                argv += ['--env-kwargs', json.dumps({'episodes_per_stage': per_stage})]
            runs.append((out, argv))
    return runs


def steps_of(run: str) -> int:
    path = Path(run) / 'run.json'
    return json.loads(path.read_text())['steps'] if path.exists() else 0


def train_all(args: argparse.Namespace) -> int:
    runs = run_specs(args)
    env = dict(os.environ, OMP_NUM_THREADS='1', MKL_NUM_THREADS='1')
    env['PYTHONPATH'] = os.pathsep.join(
        filter(None, [str(ROOT / 'src' / 'growspace_sim'), env.get('PYTHONPATH')]))
    before = {out: steps_of(out) for out, _ in runs}
    todo = [(out, argv) for out, argv in runs if before[out] < args.steps]
    Path(args.out).mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    procs = []
    for out, argv in todo:
        Path(out).mkdir(parents=True, exist_ok=True)
        log = open(Path(out) / 'train.log', 'a')
        procs.append((out, log, subprocess.Popen(
            [sys.executable, '-m', 'growspace_sim.learn.train', *argv], stdout=log,
            stderr=subprocess.STDOUT, env=env)))
    failed = 0
    for out, log, proc in procs:
        if proc.wait() != 0:
            failed += 1
            print(f'{out}: training failed (exit {proc.returncode}), see its train.log',
                  file=sys.stderr)
        log.close()
    wall = time.perf_counter() - start
    rows, gained = [], 0
    for out, _ in runs:
        info_path = Path(out) / 'run.json'
        if not info_path.exists():
            rows.append(dict(run=Path(out).name, steps=0, gained=0, call_steps_per_s=0.0))
            continue
        info = json.loads(info_path.read_text())
        leg = info['legs'][-1] if out in dict(todo) else None
        gain = info['steps'] - before[out]
        gained += gain
        rows.append(dict(run=Path(out).name, steps=info['steps'], gained=gain,
                         call_steps_per_s=leg['steps_per_s'] if leg else 0.0,
                         leg_wall_s=leg['wall_s'] if leg else 0.0))
    for row in rows:
        print(f'{row["run"]:28s} steps {row["steps"]:>9,}  +{row["gained"]:,} at '
              f'{row["call_steps_per_s"]:.0f} steps/s')
    remaining = sum(max(0, args.steps - r['steps']) for r in rows)
    rate = gained / wall if wall else 0.0
    summary = dict(processes=len(todo), failed=failed, wall_s=round(wall, 1),
                   steps_gained=gained, steps_per_s_total=round(rate, 1),
                   steps_per_s_per_process=round(rate / max(len(todo), 1), 1),
                   steps_remaining=remaining,
                   hours_left_at_this_rate=round(remaining / rate / 3600, 2) if rate else None,
                   runs=rows)
    summary['leg_steps_per_s_mean'] = round(float(np.mean(
        [r['call_steps_per_s'] for r in rows if r['gained']] or [0.0])), 1)
    name = f'call_{int(time.time())}_{args.device}_{os.getpid()}.json'
    (Path(args.out) / name).write_text(json.dumps(summary, indent=1) + '\n')
    print(f'budget: processes={len(todo)} failed={failed} wall_s={wall:.0f} '
          f'steps_gained={gained} steps_per_s_total={rate:.0f} '
          f'steps_per_s_per_process={summary["steps_per_s_per_process"]} '
          f'leg_steps_per_s_mean={summary["leg_steps_per_s_mean"]} '
          f'steps_remaining={remaining} hours_left={summary["hours_left_at_this_rate"]}')
    return 1 if failed else 0


# ---------------------------------------------------------------- export

def last_mean_return(run: Path, episodes: int = 100) -> float:
    path = run / 'episodes.csv'
    if not path.exists():
        return float('-inf')
    returns = np.loadtxt(path, delimiter=',', skiprows=1, usecols=3, ndmin=1)
    return float(returns[-episodes:].mean()) if returns.size else float('-inf')


def export(args: argparse.Namespace) -> int:
    """Small files of every run in one tarball, and each challenge's best policy's weights."""
    import torch  # noqa: PLC0415
    from growspace_sim.learn.train import load_model  # noqa: PLC0415

    out, dest = Path(args.out), Path(args.export)
    dest.mkdir(parents=True, exist_ok=True)
    runs = sorted(p.parent for p in out.glob('*/run.json'))
    with tarfile.open(dest / 'runs.tar.gz', 'w:gz') as tar:
        for run in runs:
            for name in ('run.json', 'episodes.csv', 'train.log'):
                if (run / name).exists():
                    tar.add(run / name, arcname=f'{run.name}/{name}')
            for progress in run.glob('progress*.csv'):
                tar.add(progress, arcname=f'{run.name}/{progress.name}')
        for call in out.glob('call_*.json'):
            tar.add(call, arcname=call.name)
    best: dict[str, tuple[float, Path]] = {}
    for run in runs:
        challenge = run.name.split('-')[1]  # ppo-<challenge>-<setting>-s<seed>
        score = last_mean_return(run)
        if (run / 'model.zip').exists() and score > best.get(challenge, (float('-inf'),))[0]:
            best[challenge] = (score, run)
    for challenge, (score, run) in sorted(best.items()):
        model = load_model(run, device='cpu')
        info = json.loads((run / 'run.json').read_text())
        torch.save({'state_dict': model.policy.state_dict(), 'run': run.name,
                    'env': info['env'], 'steps': info['steps'],
                    'n_envs': info['n_envs'], 'train_return_last100': score},
                   dest / f'policy-{challenge}.pt')
        print(f'{challenge}: {run.name} ({info["steps"]:,} steps, last-100 return {score:.2f})')
    return 0


# ---------------------------------------------------------------- report

def report_line(results_csv: Path, camera_jsons: list[Path], call_jsons: list[Path]) -> str:
    """Issue 32's summary line from growspace-compare's results.csv, the camera loop's JSON
    files and the train calls' call_*.json.

    ppo_beats_random: PPO's mean minus its s.e. above random's mean plus its s.e. (the ± 1 s.e.
    intervals apart); ppo_within_oracle_10pct: PPO's mean at least 0.9 x the oracle's; both
    over the cases with a PPO row. camera_ratio_min: the lowest camera / simulator return over
    the challenges, with each challenge's JSON files (halves of its seeds) pooled.
    hours_total: the training calls' wall time (calls that ended in the same minute ran side by
    side and count once: the longest).
    """
    import csv  # noqa: PLC0415

    rows: dict[str, dict[str, dict]] = defaultdict(dict)
    with open(results_csv, newline='') as f:
        for row in csv.DictReader(f):
            rows[row['case']][row['agent']] = row
    ppo = {case: agents for case, agents in rows.items() if 'ppo' in agents}
    beats = sum(float(a['ppo']['mean']) - float(a['ppo']['se'])
                > float(a['random']['mean']) + float(a['random']['se']) for a in ppo.values())
    within = sum(float(a['ppo']['mean']) >= 0.9 * float(a['oracle']['mean'])
                 for a in ppo.values())
    steps = [int(a['ppo']['steps']) for a in ppo.values()]
    runs = sum(int(a['ppo']['runs']) for a in ppo.values())
    pooled: dict[str, tuple[list, list]] = defaultdict(lambda: ([], []))
    for path in camera_jsons:
        for challenge, r in json.loads(Path(path).read_text()).items():
            pooled[challenge][0].extend(r['sim_returns'])
            pooled[challenge][1].extend(r['camera_returns'])
    ratios = [np.mean(cam) / np.mean(sim) for sim, cam in pooled.values() if np.mean(sim)]
    by_start: dict[int, float] = {}
    for path in call_jsons:  # calls that ended in the same minute ran side by side
        call = json.loads(Path(path).read_text())
        start = int(Path(path).stem.split('_')[1]) // 60
        by_start[start] = max(by_start.get(start, 0.0), call['wall_s'])
    hours = sum(by_start.values()) / 3600
    return (f'learning: runs={runs} steps_per_run={int(np.mean(steps)) if steps else 0} '
            f'ppo_beats_random={beats}/{len(ppo)} ppo_within_oracle_10pct={within}/{len(ppo)} '
            f'camera_ratio_min={min(ratios) if ratios else float("nan"):.3f} '
            f'hours_total={hours:.2f}')


def report(args: argparse.Namespace) -> int:
    print(report_line(Path(args.results), args.camera, args.calls))
    return 0


# ---------------------------------------------------------------- camera

def camera(args: argparse.Namespace) -> int:
    """Each exported policy closed loop: simulator observation vs the camera's."""
    from camera_loop import run_camera_loop  # noqa: PLC0415  (scripts/camera_loop.py)
    return run_camera_loop(args)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest='command', required=True)
    p = sub.add_parser('profile', help='where one PPO update goes')
    p.add_argument('--env', default='GrowSpace/Control-Hard-v0')
    p.add_argument('--device', default='cpu')
    p.add_argument('--updates', type=int, default=1, help='timed updates after one warm-up')
    p.add_argument('--configs', default='dummy:sb3:8,native:sb3:8,native:device:8,'
                   'native:device:32', help='vec:buffer:n_envs, comma-separated')
    p.add_argument('--json')
    t = sub.add_parser('train', help='train (or resume) every run in parallel')
    t.add_argument('--out', required=True, help='run folders (kept between calls)')
    t.add_argument('--cases', default=','.join(CASES + EXTRA_CASES))
    t.add_argument('--seeds', type=int, default=3)
    t.add_argument('--first-seed', type=int, default=0)
    t.add_argument('--steps', type=int, default=1_000_000)
    t.add_argument('--minutes', type=float, required=True, help='wall budget of this call')
    t.add_argument('--device', default='cpu')
    t.add_argument('--n-envs', type=int, default=8, help='x n_steps = 2048 per update')
    t.add_argument('--vec', default='native')
    t.add_argument('--rollout-buffer', default='device')
    t.add_argument('--checkpoint-every', type=int, default=250_000)
    t.add_argument('--export', help='also write the small files and best policies here')
    e = sub.add_parser('export', help='small files + best policies of the runs in --out')
    e.add_argument('--out', required=True)
    e.add_argument('--export', required=True)
    c = sub.add_parser('camera', help='exported policies closed loop through the camera')
    c.add_argument('--policies', required=True, help="folder of export's policy-*.pt")
    c.add_argument('--episodes', type=int, default=20)
    c.add_argument('--seed', type=int, default=10_000)
    c.add_argument('--json')
    r = sub.add_parser('report', help="issue 32's summary line")
    r.add_argument('--results', required=True, help="growspace-compare's results.csv")
    r.add_argument('--camera', nargs='*', default=[], help="camera's --json files")
    r.add_argument('--calls', nargs='*', default=[], help="train's call_*.json files")
    args = parser.parse_args(argv)
    if args.command == 'report':
        return report(args)
    if args.command == 'profile':
        return profile(args)
    if args.command == 'train':
        if ROLLOUT % args.n_envs:
            parser.error(f'--n-envs must divide {ROLLOUT}, got {args.n_envs}')
        code = train_all(args)
        return export(args) or code if args.export else code
    if args.command == 'export':
        return export(args)
    return camera(args)


if __name__ == '__main__':
    sys.exit(main())
