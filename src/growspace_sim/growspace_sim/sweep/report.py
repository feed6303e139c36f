"""The experiment's table and figures, from all trials (``growspace-compare``'s)."""

from __future__ import annotations

import csv
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from growspace_sim.learn import evaluate_policies
from growspace_sim.sweep.spec import BASELINES, LEARNERS
from growspace_sim.sweep.trials import Outcome


TRIAL_COLUMNS = ('key', 'agent', 'env', 'seed', 'status', 'mean', 'se', 'wall_s', 'error')


def summarise(outcomes: list[Outcome], out: str | os.PathLike,
              plots: bool = True) -> list[evaluate_policies.Row]:
    """Write ``trials.csv`` and ``growspace-compare``'s table and figures from all trials.

    Files in ``out``: ``trials.csv`` (one row per trial, with its error if it raised),
    ``results.csv``, ``results.md``, ``rewards.npz``, ``rewards.png`` and, with learners,
    ``training.png``.

    Returns:
        The table's rows: per eval env and agent, the mean return ± s.e. (a group's seeds are
        averaged per episode seed, the s.e. is over episode seeds, as ``growspace-compare``).
    """
    out = Path(out)
    with open(out / 'trials.csv', 'w', newline='') as f:
        writer = csv.writer(f)
        writer.writerow(TRIAL_COLUMNS)
        for o in outcomes:
            s = o.summary
            writer.writerow([o.trial.key, o.trial.agent, o.trial.env, o.trial.seed,
                             'error' if o.error else 'ok', s.get('mean', ''), s.get('se', ''),
                             s.get('wall_s', ''), o.error])
    curves: dict[str, dict[str, dict]] = {}
    runs: dict[str, list[str]] = {}
    for o in outcomes:
        if o.error:
            continue
        s = o.summary
        entry = curves.setdefault(s['eval_env'], {}).setdefault(
            s['label'], {'rewards': [], 'steps': []})
        entry['rewards'].append(np.load(o.files / 'rewards.npy'))
        if o.trial.agent in LEARNERS:
            entry['steps'].append(s['steps'])
            runs.setdefault(evaluate_policies.case_name(s['eval_env']), []).append(
                str(o.files / 'run'))
    rows = [row for env_id, results in curves.items()
            for row in evaluate_policies.rows_for(env_id, results)]
    # rows_for counts trained runs; a random agent's seeds are pooled the same way.
    rows = [replace(r, runs=len(curves[r.env][r.agent]['rewards']))
            if r.agent in BASELINES else r for r in rows]
    evaluate_policies.write_csv(rows, out / 'results.csv')
    (out / 'results.md').write_text(evaluate_policies.markdown(rows) + '\n')
    np.savez_compressed(out / 'rewards.npz', **{
        f'{env_id}|{label}': np.concatenate(entry['rewards'])
        for env_id, results in curves.items() for label, entry in results.items()})
    if plots and curves:
        evaluate_policies.plot_rewards(curves, out / 'rewards.png')
        if runs:
            evaluate_policies.plot_training(runs, out / 'training.png')
    return rows
