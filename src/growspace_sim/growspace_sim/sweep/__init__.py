"""Experiments as Ray Tune trials: agents x env ids x seeds (``growspace-sweep``).

Every trial is one agent on one env id with one seed, run by the function the single-run
commands use: ``growspace_sim.agents.evaluation.play_agent`` (``growspace-eval``) for the random
agent and the oracle, ``growspace_sim.learn.train.train`` (``growspace-train``) then
``growspace_sim.learn.evaluate_policies.evaluate_env`` (``growspace-compare``) for PPO, A2C, DQN
and Rainbow. All trials are evaluated on the same episode seeds, so the experiment's table and
reward-curve figure are ``growspace-compare``'s, from all trials.

A spec is a YAML file::

    name: control-baselines    # the experiment; its folder is runs/sweeps/<name>
    episodes: 60               # evaluation episodes per trial: seeds eval_seed, eval_seed + 1, ...
    eval_seed: 10000
    runs:                      # groups; each is the grid agents x envs x seeds
      - agents: [random, oracle]
        envs: [GrowSpace/Control-Easy-v0, GrowSpace/Control-Hard-v0]
      - agents: [ppo]
        envs: [GrowSpace/Control-Hard-v0]
        seeds: 3               # 0, 1, 2 (or a list)
        steps: 100000
        hp: {n_steps: 256, batch_size: 64}
        n_envs: 8

Group keys: ``agents``, ``envs``, ``seeds`` (default 1), and for learners ``steps`` (required),
``hp``, ``n_envs``, ``max_minutes``, ``device``; ``env_kwargs`` (``gymnasium.make`` keywords,
e.g. ``SimConfig`` fields) and ``label`` (the table's agent column) for any agent. The random
agent's actions are seeded with ``eval_seed + seed``, so seed 0 plays what ``growspace-eval
--seed <eval_seed>`` and ``growspace-compare`` play; the oracle is deterministic and gets one
trial per env whatever the seeds.

Usage::

    growspace-sweep config/sweeps/reference_agents.yaml --workers 2
    growspace-sweep --agents random,oracle --envs GrowSpace/Control-Easy-v0 --seeds 4 \\
        --episodes 20 --name quick
    growspace-sweep SPEC --address HEAD_IP:6379 --storage /shared/sweeps     # a Ray cluster

Ray: a local instance bound to 127.0.0.1 (no dashboard, no usage stats, nothing sent beyond
loopback, its session folders in a folder only this user can enter; see ``connect``), stopped
completely at the end of the sweep, unless ``--address`` or ``RAY_ADDRESS`` names a cluster.
Run the same command again after an interruption: finished trials are kept, the others run
(``--retry-errored`` also reruns failed ones).

Modules: ``spec`` (the spec and its validation), ``trials`` (Ray Tune: running, resuming,
staying on loopback), ``cluster`` (joining a cluster: its token checked first), ``report``
(table and figures) and ``cli`` (``growspace-sweep``, also ``python -m growspace_sim.sweep``).
"""

from growspace_sim.sweep.cli import main
from growspace_sim.sweep.report import summarise, TRIAL_COLUMNS
from growspace_sim.sweep.spec import (
    BASELINES, flags_spec, LEARNERS, load_spec, parse_spec, Spec, SpecError, Trial)
from growspace_sim.sweep.trials import (
    connect, disconnect, LOCAL_ONLY_ENV, LOOPBACK, Outcome, private_temp_dir, run_sweep,
    run_trial)

__all__ = ['BASELINES', 'LEARNERS', 'LOCAL_ONLY_ENV', 'LOOPBACK', 'Outcome', 'Spec', 'SpecError',
           'TRIAL_COLUMNS', 'Trial', 'connect', 'disconnect', 'flags_spec', 'load_spec', 'main',
           'parse_spec', 'private_temp_dir', 'run_sweep', 'run_trial', 'summarise']
