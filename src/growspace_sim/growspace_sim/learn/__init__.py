"""Learned baselines for GrowSpace: PPO, A2C, DQN and Rainbow with a CNN encoder.

Optional extra: ``pip install -r requirements-learn.txt`` (torch, Stable-Baselines3, pandas,
matplotlib, tqdm/rich). The core package and its tests never import this subpackage.

Entry points::

    growspace-train --algo ppo --env GrowSpace/Control-Easy-v0 --steps 100000 --seed 0
    growspace-compare --run runs/ppo-control-easy-s0 --episodes 50 --out results/

Policy files (a run's ``model.zip``, checkpoints) are pickles: loading one runs code it
contains. Load only files you made.
"""
