"""Learned baselines for GrowSpace: PPO, A2C, DQN and Rainbow with a CNN encoder.

Optional extra: ``pip install -r requirements-learn.txt`` (torch, Stable-Baselines3, pandas,
matplotlib, tqdm/rich). The core package and its tests never import this subpackage.

Entry points::

    growspace-train --algo ppo --env GrowSpace/Control-Easy-v0 --steps 100000 --seed 0
    growspace-compare --run runs/ppo-control-easy-s0 --episodes 50 --out results/

Policy files (a run's ``model.zip``, checkpoints) are pickles: loading one runs code it
contains. Load only files you made.
"""

from __future__ import annotations

from collections.abc import Sequence
import importlib.util
import sys

NEEDS = ('torch', 'stable_baselines3')  # what training imports; requirements-learn.txt has them


def missing() -> list[str]:
    """The learn extra's modules that are not installed."""
    return [name for name in NEEDS if importlib.util.find_spec(name) is None]


def train_main(argv: Sequence[str] | None = None) -> int:
    """Console script ``growspace-train``: one line naming what is missing, not a traceback."""
    absent = missing()
    if absent:
        print(f'growspace-train: needs the learn extra ({", ".join(absent)} not installed): '
              'pip install -r requirements-learn.txt', file=sys.stderr)
        return 2
    from growspace_sim.learn.train import main  # noqa: PLC0415 - torch only when present

    return main(None if argv is None else list(argv))
