"""Trained policies vs the random agent and the oracle on the same seeds (``growspace-compare``).

For each env among the given runs, the random agent, the oracle and every run's policy play the
same seeded episodes. Writes, into ``--out``::

    results.csv     case, env, agent, runs, episodes, steps, mean, se
    results.md      the same as a markdown table (mean ± s.e. of the 50-step return)
    rewards.png     cumulative reward over the episode, mean ± 1 s.d., one panel per case
    training.png    training return vs env steps per run group (from each run's episodes.csv)

A run trained on the MNIST curriculum is evaluated on all ten digits
(``GrowSpace/Shape-AllDigits-v0``), like the run trained on random digits. Usage::

    growspace-compare --run runs/ppo-control-easy-s0 --run runs/ppo-control-easy-s1 --out results

Security: a run's ``model.zip`` is a pickle. Stable-Baselines3 restores parts of it with
cloudpickle, so loading one runs code it contains: pass ``--run`` only directories you made
(``growspace-train``), or ones you would run as code.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import warnings
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import growspace_sim  # noqa: F401  (registers the ids)
from growspace_sim import arguments, learn
from growspace_sim.agents import evaluation

EVAL_ENV = {'GrowSpace/Shape-Curriculum-v0': 'GrowSpace/Shape-AllDigits-v0'}
COLUMNS = ('case', 'env', 'agent', 'runs', 'episodes', 'steps', 'mean', 'se')
BASELINE_AGENTS = ('random', 'oracle')


@dataclass(frozen=True)
class Row:
    case: str       # e.g. control/easy
    env: str        # the id the episodes were played on
    agent: str      # random, oracle, or the run label (algo, or algo + training env)
    runs: int       # trained runs (seeds) pooled in this row; 0 or the seeds of a baseline
    episodes: int   # episode seeds, the same for every agent and run
    steps: int      # mean training steps of the pooled runs
    mean: float     # mean undiscounted episode return
    se: float       # its standard error over the pooled episodes


class PolicyAgent:
    """A Stable-Baselines3 model behind the ``Agent`` protocol (``growspace_sim.agents``)."""

    def __init__(self, model, deterministic: bool = True) -> None:
        self.model, self.deterministic = model, deterministic

    def act(self, observation: np.ndarray, env: gym.Env) -> int:
        action, _ = self.model.predict(observation, deterministic=self.deterministic)
        return int(action)


def case_name(env_id: str) -> str:
    """``GrowSpace/FindPlant-Hard-v0`` -> ``find_plant/hard``; shape digit sets keep their name."""
    from growspace_sim.core import task as tasks  # noqa: PLC0415
    name = env_id.split('/')[-1].rsplit('-', 1)[0]
    challenge, _, setting = name.partition('-')
    by_title = {task.env_name: task.name for task in tasks.all_tasks()}
    return f'{by_title.get(challenge, challenge.lower())}/{setting.lower()}'


def evaluate_env(env_id: str, runs: list[str], episodes: int, seed: int = 10_000,
                 deterministic: bool = True, baselines: bool = True) -> dict[str, dict]:
    """Random, oracle and each run on ``episodes`` seeded episodes of ``env_id``.

    Every agent plays the same seeds through ``agents.evaluation.evaluate``, as in
    ``growspace-eval``; runs with the same label (seeds of one algorithm) are pooled.

    Returns ``{label: {'rewards': (n, 50) array per run, 'steps': [...]}}``; random and
    oracle have one entry each.
    """
    agents: dict[str, evaluation.AgentFactory] = {}
    if baselines:
        agents.update({name: lambda env, name=name: evaluation.make_agent(name, env, seed)
                       for name in BASELINE_AGENTS})
    infos = {run: json.loads((Path(run) / 'run.json').read_text()) for run in runs}
    if runs:  # random and oracle alone need no torch
        import torch  # noqa: PLC0415

        from growspace_sim.learn.train import load_model  # noqa: PLC0415
        torch.set_num_threads(1)
        agents.update({run: lambda env, run=run: PolicyAgent(load_model(run, device='cpu'),
                                                             deterministic) for run in runs})
    played = evaluation.evaluate(env_id, agents, range(seed, seed + episodes))
    results: dict[str, dict] = defaultdict(lambda: {'rewards': [], 'steps': []})
    for key, episodes_played in played.items():
        entry = results[run_label(infos[key]) if key in infos else key]
        entry['rewards'].append(episodes_played.rewards)
        if key in infos:
            entry['steps'].append(infos[key]['steps'])
    return dict(results)


def run_label(info: dict) -> str:
    """The agent column: the algo, plus the training env when it differs from the eval env."""
    if info['env'] in EVAL_ENV:
        return f'{info["algo"]} ({info["env"].split("/")[-1].rsplit("-", 1)[0].lower()})'
    if 'AllDigits' in info['env']:
        return f'{info["algo"]} (shape-alldigits)'
    return info['algo']


def rows_for(env_id: str, results: dict[str, dict]) -> list[Row]:
    """One row per agent. Runs (seeds) play the same episode seeds, so a run group's return for
    an episode seed is the mean over its runs, and the s.e. is taken over the episode seeds:
    pooling runs x episodes as independent samples would shrink it by up to sqrt(runs) even when
    every run learned the same policy.
    """
    rows = []
    for label, entry in results.items():
        returns = np.mean([evaluation.episode_returns(r) for r in entry['rewards']], axis=0)
        se = evaluation.mean_se(returns)[1]
        steps = int(np.mean(entry['steps'])) if entry['steps'] else 0
        rows.append(Row(case_name(env_id), env_id, label, len(entry['steps']), int(returns.size),
                        steps, float(returns.mean()), float(se)))
    return rows


def markdown(rows: list[Row]) -> str:
    lines = ['| case | agent | runs (seeds) | training steps | episodes | return (mean ± s.e.) |',
             '|---|---|---|---|---|---|']
    for r in rows:
        steps = f'{r.steps:,}' if r.steps else '-'
        lines.append(f'| {r.case} | {r.agent} | {r.runs or "-"} | {steps} | {r.episodes} '
                     f'| {r.mean:.2f} ± {r.se:.2f} |')
    return '\n'.join(lines)


def write_csv(rows: list[Row], path: Path) -> None:
    with open(path, 'w', newline='') as f:
        writer = csv.writer(f)
        writer.writerow(COLUMNS)
        for r in rows:
            writer.writerow([getattr(r, c) for c in COLUMNS])


def _panels(n: int) -> tuple[Any, Any]:
    """A figure with one small panel per case, four per row; unused panels hidden."""
    import matplotlib  # noqa: PLC0415
    matplotlib.use('Agg')  # files only, no display
    import matplotlib.pyplot as plt  # noqa: PLC0415
    cols = min(n, 4)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.9 * rows), squeeze=False)
    for ax in list(axes.flat)[n:]:
        ax.axis('off')
    return fig, axes


def _save(fig: Any, path: Path) -> None:
    import matplotlib.pyplot as plt  # noqa: PLC0415
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_rewards(curves: dict[str, dict[str, dict]], path: Path) -> None:
    """One panel per eval env: cumulative reward vs step, mean ± 1 s.d. (the paper's figure)."""
    fig, axes = _panels(len(curves))
    for ax, (env_id, results) in zip(axes.flat, curves.items()):
        for label, entry in results.items():
            cumulative = np.cumsum(np.concatenate(entry['rewards']), axis=1)
            mean, sd = cumulative.mean(axis=0), cumulative.std(axis=0)
            x = np.arange(1, mean.size + 1)
            style = {'random': ':', 'oracle': '--'}.get(label, '-')
            ax.plot(x, mean, style, label=label)
            ax.fill_between(x, mean - sd, mean + sd, alpha=0.2)
        ax.set_title(case_name(env_id), fontsize=10)
        ax.set_xlabel('step')
        ax.set_ylabel('cumulative reward')
        ax.legend(fontsize=7)
    _save(fig, path)


def plot_training(groups: dict[str, list[str]], path: Path, bins: int = 30) -> None:
    """Training return vs env steps, binned, mean ± s.d. over the runs of each group."""
    fig, axes = _panels(len(groups))
    for ax, (title, runs) in zip(axes.flat, groups.items()):
        for label, run_list in _by_label(runs).items():
            curves, edges = [], None
            data = [np.loadtxt(Path(r) / 'episodes.csv', delimiter=',', skiprows=1,
                               usecols=(0, 3), ndmin=2) for r in run_list]
            data = [d for d in data if d.size]
            if not data:
                continue
            top = min(d[-1, 0] for d in data)
            edges = np.linspace(0, top, bins + 1)
            for d in data:
                index = np.clip(np.digitize(d[:, 0], edges) - 1, 0, bins - 1)
                sums = np.bincount(index, d[:, 1], bins)
                counts = np.bincount(index, minlength=bins)
                curves.append(np.where(counts > 0, sums / np.maximum(counts, 1), np.nan))
            curves = np.array(curves)
            with warnings.catch_warnings():  # bins without a finished episode stay NaN
                warnings.simplefilter('ignore', RuntimeWarning)
                mean, sd = np.nanmean(curves, axis=0), np.nanstd(curves, axis=0)
            x = 0.5 * (edges[1:] + edges[:-1])
            ax.plot(x, mean, label=f'{label} ({len(data)} seeds)')
            ax.fill_between(x, mean - sd, mean + sd, alpha=0.2)
        ax.set_title(title, fontsize=10)
        ax.set_xlabel('env steps')
        ax.set_ylabel('training episode return')
        ax.legend(fontsize=7)
    _save(fig, path)


def _by_label(runs: list[str]) -> dict[str, list[str]]:
    groups: dict[str, list[str]] = defaultdict(list)
    for run in runs:
        info = json.loads((Path(run) / 'run.json').read_text())
        groups[run_label(info)].append(run)
    return dict(groups)


def eval_env_of(run: str) -> str:
    env_id = json.loads((Path(run) / 'run.json').read_text())['env']
    return EVAL_ENV.get(env_id, env_id)


def compare(runs: list[str], episodes: int, out: str | Path, seed: int = 10_000,
            workers: int = 1, deterministic: bool = True, plots: bool = True) -> list[Row]:
    """Evaluate every run (grouped by eval env), write results.{csv,md} and the figures."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    by_env: dict[str, list[str]] = defaultdict(list)
    for run in runs:
        by_env[eval_env_of(run)].append(run)
    jobs = {env_id: (env_id, env_runs, episodes, seed, deterministic)
            for env_id, env_runs in by_env.items()}
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            futures = {k: pool.submit(evaluate_env, *a) for k, a in jobs.items()}
            curves = {k: f.result() for k, f in futures.items()}
    else:
        curves = {k: evaluate_env(*a) for k, a in jobs.items()}
    rows = [row for env_id, results in curves.items() for row in rows_for(env_id, results)]
    write_csv(rows, out / 'results.csv')
    (out / 'results.md').write_text(markdown(rows) + '\n')
    np.savez_compressed(out / 'rewards.npz', **{
        f'{env_id}|{label}': np.concatenate(entry['rewards'])
        for env_id, results in curves.items() for label, entry in results.items()})
    if plots:
        plot_rewards(curves, out / 'rewards.png')
        plot_training({case_name(e): r for e, r in by_env.items()}, out / 'training.png')
    return rows


def load_results(eval_dir: str | Path) -> tuple[list[Row], dict[str, dict[str, dict]]]:
    """Rows and reward curves that ``compare`` wrote into ``eval_dir`` (to merge several)."""
    eval_dir = Path(eval_dir)
    rows = []
    with open(eval_dir / 'results.csv', newline='') as f:
        for record in csv.DictReader(f):
            rows.append(Row(record['case'], record['env'], record['agent'], int(record['runs']),
                            int(record['episodes']), int(record['steps']),
                            float(record['mean']), float(record['se'])))
    runs = {(r.env, r.agent): max(r.runs, 1) for r in rows}
    steps = {(r.env, r.agent): r.steps for r in rows}
    curves: dict[str, dict[str, dict]] = defaultdict(dict)
    with np.load(eval_dir / 'rewards.npz') as data:
        for key in data.files:
            env_id, label = key.split('|', 1)
            n = runs[env_id, label]
            rewards = data[key].reshape(n, -1, data[key].shape[-1])
            curves[env_id][label] = {'rewards': list(rewards),
                                     'steps': [steps[env_id, label]] * n if label not in
                                     BASELINE_AGENTS else []}
    rows = [row for env_id, results in curves.items() for row in rows_for(env_id, results)]
    return rows, dict(curves)


def main(argv: list[str] | None = None) -> int:
    parser = arguments.Parser(prog='growspace-compare', description=__doc__.splitlines()[0],
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--run', action='append', required=True,
                        help='a run directory from growspace-train (repeatable); its '
                             'model.zip is a pickle that runs code when loaded: only your own')
    parser.add_argument('--episodes', type=arguments.integer(2), default=50,
                        help='episodes per agent and run (2 or more: a standard error)')
    parser.add_argument('--seed', type=arguments.SEED, default=10_000, help='first episode seed')
    parser.add_argument('--out', type=arguments.folder, default='results')
    parser.add_argument('--workers', type=arguments.integer(1), default=1,
                        help='processes (one per env)')
    parser.add_argument('--stochastic', action='store_true', help='sample policy actions')
    parser.add_argument('--no-plots', action='store_true')
    args = parser.parse_args(argv)
    for run in args.run:
        if not (Path(run) / 'run.json').exists():
            parser.error(f'{run} is not a run directory (no run.json)')
    absent = learn.missing()
    if absent:
        print(f'growspace-compare: loading a policy needs the learn extra ({", ".join(absent)} '
              'not installed): pip install -r requirements-learn.txt', file=sys.stderr)
        return 2
    rows = compare(args.run, args.episodes, args.out, args.seed, args.workers,
                   not args.stochastic, not args.no_plots)
    print(markdown(rows))
    return 0


if __name__ == '__main__':
    sys.exit(main())
