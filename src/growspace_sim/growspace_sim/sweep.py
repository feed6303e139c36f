"""Experiments as Ray Tune trials: agents x env ids x seeds (``growspace-sweep``).

Every trial is one agent on one env id with one seed, run by the function the single-run
commands use: ``growspace_sim.evaluate.play_agent`` (``growspace-eval``) for the random agent and
the oracle, ``growspace_sim.learn.train.train`` (``growspace-train``) then
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
loopback; see ``connect``) unless ``--address`` or ``RAY_ADDRESS`` names a cluster. Run the
same command again after an interruption: finished trials are kept, the others run
(``--retry-errored`` also reruns failed ones).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import importlib.util
import json
import math
import os
import re
import shutil
import socket
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterator, Mapping

import gymnasium as gym
import numpy as np
import yaml

import growspace_sim  # noqa: F401  (registers the ids)
from growspace_sim import evaluate
from growspace_sim.learn import evaluate_policies

BASELINES = evaluate.AGENTS
LEARNERS = ('ppo', 'a2c', 'dqn', 'rainbow')  # growspace_sim.learn.train.ALGOS, without torch
SPEC_KEYS = ('name', 'episodes', 'eval_seed', 'runs')
GROUP_KEYS = ('agents', 'envs', 'seeds', 'steps', 'hp', 'n_envs', 'max_minutes', 'device',
              'env_kwargs', 'label')
LEARNER_KEYS = ('steps', 'hp', 'n_envs', 'max_minutes', 'device')
LOOPBACK = '127.0.0.1'
# Ray 2.60 starts a minimal dashboard process even without the dashboard, and its usage module
# asks the cloud metadata addresses (169.254.169.254, metadata.google.internal) which cloud it
# runs on, whatever RAY_USAGE_STATS_ENABLED says. That HTTP client honours the proxy variables:
# the local instance's processes send it to a closed loopback port (no DNS query, no packet
# leaves), while Ray's own gRPC and HTTP to 127.0.0.1 stay direct.
_NO_PROXY = f'{LOOPBACK},localhost,::1'
LOCAL_ONLY_ENV = {name: value for names, value in (
    (('http_proxy', 'https_proxy', 'HTTP_PROXY', 'HTTPS_PROXY'), f'http://{LOOPBACK}:9'),
    (('no_proxy', 'NO_PROXY'), _NO_PROXY)) for name in names}
TRIAL_COLUMNS = ('key', 'agent', 'env', 'seed', 'status', 'mean', 'se', 'wall_s', 'error')


class SpecError(ValueError):
    """A sweep spec with a missing, unknown or invalid field."""


@dataclass(frozen=True)
class Trial:
    """One agent on one env id with one seed: the unit Ray Tune schedules."""

    agent: str                  # random, oracle, ppo, a2c, dqn or rainbow
    env: str                    # the training (or playing) env id
    seed: int                   # training seed; the random agent's action seed is eval_seed + seed
    episodes: int               # evaluation episodes
    eval_seed: int              # first evaluation episode seed
    steps: int = 0              # training steps (learners)
    label: str = ''             # the table's agent column; '' = the agent (or run) name
    hp: dict = field(default_factory=dict)
    env_kwargs: dict = field(default_factory=dict)
    n_envs: int | None = None
    max_minutes: float | None = None
    device: str = 'cpu'

    @property
    def key(self) -> str:
        """A readable, unique file name, e.g. ``ppo-control-hard-s2``."""
        name = self.env.split('/')[-1].rsplit('-', 1)[0].lower()
        return re.sub(r'[^a-z0-9_.-]+', '_', f'{self.label or self.agent}-{name}-s{self.seed}'
                      .lower())


@dataclass(frozen=True)
class Spec:
    """A validated experiment: its name, evaluation episodes and trials."""

    name: str
    episodes: int
    eval_seed: int
    trials: tuple[Trial, ...]


@dataclass(frozen=True)
class Outcome:
    """A finished (or failed) trial as the experiment sees it."""

    trial: Trial
    error: str = ''             # 'ExceptionType: message' when the trial raised
    files: Path | None = None   # the trial's files (a copy of its Ray checkpoint)
    summary: dict = field(default_factory=dict)  # trial.json


def load_spec(path: str | os.PathLike) -> Spec:
    """Read and validate a YAML spec file.

    Raises:
        SpecError: naming the field, the value and what is allowed.
    """
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as error:
        raise SpecError(f'Cannot read the spec {path}: {error}') from error
    return parse_spec(data, default_name=Path(path).stem)


def parse_spec(data: Any, default_name: str = 'sweep') -> Spec:
    """Validate a spec mapping (see the module docstring) and expand its trials.

    Raises:
        SpecError: naming the field, the value and what is allowed.
    """
    if not isinstance(data, Mapping):
        raise SpecError(f'A spec is a mapping with keys {", ".join(SPEC_KEYS)}; '
                        f'got {type(data).__name__}.')
    _check_keys(data, SPEC_KEYS, 'spec')
    name = data.get('name', default_name)
    if not isinstance(name, str) or not re.fullmatch(r'[A-Za-z0-9_.-]+', name):
        raise SpecError(f'name must be letters, digits, "_", "." or "-"; got {name!r}.')
    episodes = _integer(data.get('episodes', 50), 'episodes', minimum=2)
    eval_seed = _integer(data.get('eval_seed', 10_000), 'eval_seed', minimum=0)
    groups = data.get('runs')
    if not isinstance(groups, list) or not groups:
        raise SpecError(f'runs must be a non-empty list of groups; got {groups!r}.')
    trials: dict[str, tuple[Trial, str]] = {}
    for index, group in enumerate(groups):
        where = f'runs[{index}]'
        for trial in _expand(group, where, episodes, eval_seed):
            if trial.key in trials:
                other = trials[trial.key][1]
                raise SpecError(f'{where}: trial {trial.key} is also in {other}; give one '
                                'group a distinct label.')
            trials[trial.key] = (trial, where)
    return Spec(name, episodes, eval_seed, tuple(t for t, _ in trials.values()))


def flags_spec(args: argparse.Namespace) -> Spec:
    """A one-group spec from ``--agents --envs --seeds --steps --episodes --eval-seed``."""
    group: dict[str, Any] = {'agents': args.agents.split(','), 'envs': args.envs.split(','),
                             'seeds': _seeds_flag(args.seeds)}
    if args.steps is not None:
        group['steps'] = args.steps
    return parse_spec({'name': args.name or 'sweep', 'episodes': args.episodes,
                       'eval_seed': args.eval_seed, 'runs': [group]})


def _seeds_flag(text: str) -> int | list[int]:
    try:
        return int(text) if ',' not in text else [int(s) for s in text.split(',')]
    except ValueError as error:
        raise SpecError(f'--seeds takes a count or a comma-separated list; got {text!r}.') \
            from error


def _expand(group: Any, where: str, episodes: int, eval_seed: int) -> list[Trial]:
    if not isinstance(group, Mapping):
        raise SpecError(f'{where} must be a mapping with keys {", ".join(GROUP_KEYS)}; '
                        f'got {group!r}.')
    _check_keys(group, GROUP_KEYS, where)
    agents = _names(group.get('agents'), f'{where}.agents', BASELINES + LEARNERS)
    envs = _names(group.get('envs'), f'{where}.envs', _env_ids())
    seeds = group.get('seeds', 1)
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        seeds = list(range(_integer(seeds, f'{where}.seeds', minimum=1)))
    elif isinstance(seeds, list) and seeds:
        seeds = [_integer(s, f'{where}.seeds[{i}]', minimum=0) for i, s in enumerate(seeds)]
    else:
        raise SpecError(f'{where}.seeds must be a count >= 1 or a non-empty list of seeds; '
                        f'got {seeds!r}.')
    learners = [a for a in agents if a in LEARNERS]
    if not learners:
        extra = sorted(set(group) & set(LEARNER_KEYS))
        if extra:
            raise SpecError(f'{where}: {", ".join(extra)} only apply to learners '
                            f'({", ".join(LEARNERS)}); the group has {agents}.')
    options: dict[str, Any] = {
        'label': _text(group.get('label', ''), f'{where}.label'),
        'env_kwargs': _mapping(group.get('env_kwargs', {}), f'{where}.env_kwargs')}
    if learners:
        if 'steps' not in group:
            raise SpecError(f'{where}: steps is required for {", ".join(learners)}.')
        if not importlib.util.find_spec('stable_baselines3'):
            raise SpecError(f'{where}: agents {learners} need the learn extra '
                            '(pip install -r requirements-learn.txt).')
        options.update(steps=_integer(group['steps'], f'{where}.steps', minimum=1),
                       hp=_mapping(group.get('hp', {}), f'{where}.hp'),
                       device=_text(group.get('device', 'cpu'), f'{where}.device'))
        if 'n_envs' in group:
            options['n_envs'] = _integer(group['n_envs'], f'{where}.n_envs', minimum=1)
        if 'max_minutes' in group:
            options['max_minutes'] = _positive(group['max_minutes'], f'{where}.max_minutes')
    trials = []
    for agent in agents:
        for env in envs:
            if agent == 'oracle' and gym.spec(env).kwargs.get('continuous'):
                raise SpecError(f'{where}: the oracle acts through discrete actions; '
                                f'{env} is continuous.')
            for seed in seeds[:1] if agent == 'oracle' else seeds:
                kwargs = options if agent in LEARNERS else {
                    k: v for k, v in options.items() if k not in LEARNER_KEYS}
                trials.append(Trial(agent, env, seed, episodes, eval_seed, **kwargs))
    return trials


def _env_ids() -> tuple[str, ...]:
    return tuple(sorted(k for k in gym.registry if k.startswith('GrowSpace/')))


def _check_keys(data: Mapping, allowed: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(map(str, data)) - set(allowed))
    if unknown:
        raise SpecError(f'{where}: unknown key(s) {", ".join(unknown)}; '
                        f'allowed: {", ".join(allowed)}.')


def _names(value: Any, where: str, allowed: tuple[str, ...]) -> list[str]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value:
        raise SpecError(f'{where} must be a non-empty list; got {value!r}.')
    for item in value:
        if item not in allowed:
            raise SpecError(f'{where}: unknown {item!r}; allowed: {", ".join(allowed)}.')
    if len(set(value)) != len(value):
        raise SpecError(f'{where} lists a name twice: {value}.')
    return list(value)


def _integer(value: Any, where: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise SpecError(f'{where} must be an integer >= {minimum}; got {value!r}.')
    return value


def _positive(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value <= 0:
        raise SpecError(f'{where} must be a number > 0; got {value!r}.')
    return float(value)


def _mapping(value: Any, where: str) -> dict:
    if not isinstance(value, Mapping):
        raise SpecError(f'{where} must be a mapping; got {value!r}.')
    return dict(value)


def _text(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise SpecError(f'{where} must be a string; got {value!r}.')
    return value


def run_trial(trial: Trial, out: Path) -> dict[str, float]:
    """Run one trial without Ray, writing its files into ``out``.

    Files: ``trial.json`` (the trial, where and when it ran, its result), ``evaluation.csv``
    (one row per evaluation episode), ``rewards.npy`` (per-step evaluation rewards, shape
    (episodes, steps)) and, for learners, ``run/`` (``growspace-train``'s run directory: CSV
    logs, checkpoints, ``model.zip``).

    Returns:
        ``mean`` and ``se`` of the evaluation return, and the trial's ``wall_s``.
    """
    started, start = time.time(), time.perf_counter()
    eval_env = evaluate_policies.EVAL_ENV.get(trial.env, trial.env)
    success = None
    if trial.agent in BASELINES:
        played = evaluate.play_agent(eval_env, trial.agent, trial.episodes, trial.eval_seed,
                                     trial.eval_seed + trial.seed, trial.env_kwargs)
        rewards, success, label, steps = played.rewards, played.success, trial.agent, 0
    else:
        rewards, eval_env, label, steps = _train_and_evaluate(trial, out / 'run')
    returns = rewards.sum(axis=1)
    mean, se = evaluate.mean_se(returns)
    wall = time.perf_counter() - start
    np.save(out / 'rewards.npy', rewards)
    with open(out / 'evaluation.csv', 'w', newline='') as f:
        writer = csv.writer(f)
        writer.writerow(['episode_seed', 'return', 'success'])
        for i, value in enumerate(returns):
            writer.writerow([trial.eval_seed + i, repr(float(value)),
                             '' if success is None else int(success[i])])
    summary = dict(trial=asdict(trial), key=trial.key, label=trial.label or label,
                   eval_env=eval_env, steps=steps, mean=mean, se=se, wall_s=round(wall, 3),
                   host=socket.gethostname(), pid=os.getpid(),
                   started=datetime.fromtimestamp(started, timezone.utc).isoformat())
    (out / 'trial.json').write_text(json.dumps(summary, indent=2) + '\n')
    return {'mean': mean, 'se': se, 'wall_s': wall}


def _train_and_evaluate(trial: Trial, run_dir: Path) -> tuple[np.ndarray, str, str, int]:
    from growspace_sim.learn import train  # noqa: PLC0415  (needs torch)
    max_seconds = trial.max_minutes * 60 if trial.max_minutes else None
    run = str(train.train(trial.agent, trial.env, trial.steps, trial.seed, run_dir,
                          trial.n_envs, trial.device, trial.hp, trial.env_kwargs,
                          progress_bar=False, max_seconds=max_seconds))
    eval_env = evaluate_policies.eval_env_of(run)
    results = evaluate_policies.evaluate_env(eval_env, [run], trial.episodes, trial.eval_seed,
                                             baselines=False)
    [(label, entry)] = results.items()
    return entry['rewards'][0], eval_env, label, int(entry['steps'][0])


def _tune_trial(config: dict, trials: dict[str, dict]) -> None:
    """The Ray Tune function trainable: run the trial, report its files as the checkpoint."""
    from ray import tune  # noqa: PLC0415
    trial = Trial(**trials[config['trial']])
    with tempfile.TemporaryDirectory(prefix=f'growspace-{trial.key}-') as tmp:
        metrics = run_trial(trial, Path(tmp))
        tune.report(metrics, checkpoint=tune.Checkpoint.from_directory(tmp))


def connect(address: str | None, workers: int | None) -> None:
    """Connect to a Ray cluster, or start a local instance bound to 127.0.0.1.

    Args:
        address: A cluster's address (``ray start --head`` prints it); ``None`` reads
            ``RAY_ADDRESS`` and, without it, starts a local instance with no dashboard.
        workers: CPUs of the local instance (default: all cores); unused for a cluster.

    Raises:
        RuntimeError: A local instance would not stay on loopback (``ray`` was imported
            before this call; see the comment below).
    """
    os.environ['RAY_USAGE_STATS_ENABLED'] = '0'  # Ray's usage report would leave the machine
    address = address or os.environ.get('RAY_ADDRESS')
    if not address:
        # On Linux, Ray 2.60 swaps a loopback node address for the machine's outward one (and
        # its servers then listen on every interface) unless multi-node clusters are disabled,
        # Ray's switch for Windows and macOS, read when ray is first imported. A local
        # instance is no cluster: with the switch off, every Ray process listens on and talks
        # to 127.0.0.1 only (the Ray processes inherit the variable).
        os.environ['RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER'] = '0'
    import ray  # noqa: PLC0415
    if ray.is_initialized():
        return
    if address:
        ray.init(address=address, log_to_driver=False)
        return
    if ray.util.get_node_ip_address() != LOOPBACK:
        raise RuntimeError('ray was imported before growspace_sim.sweep.connect(), so a local '
                           'Ray would not stay on 127.0.0.1; set '
                           'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0 before importing ray.')
    with _environ(LOCAL_ONLY_ENV):
        ray.init(address='local', num_cpus=workers, include_dashboard=False,
                 _node_ip_address=LOOPBACK, log_to_driver=False)


@contextlib.contextmanager
def _environ(values: Mapping[str, str]) -> Iterator[None]:
    """Set environment variables for the processes started inside the block."""
    saved = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def run_sweep(spec: Spec, out: str | os.PathLike, storage: str | None = None,
              workers: int | None = None, cpus_per_trial: float = 1.0,
              gpus_per_trial: float = 0.0, retry_errored: bool = False,
              verbose: int = 1, reuse_actors: bool = True) -> list[Outcome]:
    """Run (or resume) the spec's trials on the Ray instance ``connect`` set up.

    Args:
        spec: The experiment.
        out: Local folder of the experiment's results (``spec.json``, ``trials/<key>/``).
        storage: Ray Tune's storage (a path every node sees, or a URI); default ``out``.
        workers: Trials at once at most (default: as many as the resources allow). A
            resumed experiment keeps its first run's ``workers`` and ``reuse_actors``.
        cpus_per_trial: CPUs Ray reserves for each trial.
        gpus_per_trial: GPUs Ray reserves for each trial.
        retry_errored: On a resumed experiment, run the failed trials again.
        verbose: Ray Tune's verbosity (0 silent, 1 a status table now and then).
        reuse_actors: Run the next trial in a finished trial's worker process (on 2 cores
            this cuts Ray's cost per trial from about 2 s to 0.4 s; docs/baselines.md).

    Returns:
        One outcome per trial, in spec order; trials an interruption left unfinished are
        missing.

    Raises:
        SpecError: ``out`` holds an experiment with another spec.
    """
    from ray import tune  # noqa: PLC0415
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    recorded = out / 'spec.json'
    text = json.dumps({'name': spec.name, 'trials': [asdict(t) for t in spec.trials]},
                      indent=1, sort_keys=True) + '\n'
    if recorded.exists() and recorded.read_text() != text:
        raise SpecError(f'{out} holds experiment {spec.name!r} with a different spec; '
                        'resume it with the same spec, or choose another --out.')
    recorded.write_text(text)
    storage_path, name = (storage, spec.name) if storage else (str(out), 'tune')
    path = f'{storage_path.rstrip("/")}/{name}'
    by_key = {t.key: t for t in spec.trials}
    trainable = tune.with_resources(
        tune.with_parameters(_tune_trial, trials={k: asdict(t) for k, t in by_key.items()}),
        {'cpu': cpus_per_trial, 'gpu': gpus_per_trial})
    # Given again on restore: Tune creates the trials it had not created yet from it.
    param_space = {'trial': tune.grid_search(list(by_key))}
    if tune.Tuner.can_restore(path):
        tuner = tune.Tuner.restore(path, trainable, restart_errored=retry_errored,
                                   param_space=param_space)
    else:
        tuner = tune.Tuner(
            trainable,
            param_space=param_space,
            tune_config=tune.TuneConfig(max_concurrent_trials=workers,
                                        reuse_actors=reuse_actors,
                                        trial_name_creator=_trial_key,
                                        trial_dirname_creator=_trial_key),
            run_config=tune.RunConfig(name=name, storage_path=storage_path, verbose=verbose,
                                      failure_config=tune.FailureConfig(max_failures=0)))
    outcomes: dict[str, Outcome] = {}
    for result in tuner.fit():
        trial = by_key[result.config['trial']]
        if result.error is not None:
            outcomes[trial.key] = Outcome(trial, error=_error_text(result.error))
        elif result.checkpoint is not None:
            files = out / 'trials' / trial.key
            with result.checkpoint.as_directory() as directory:
                shutil.copytree(directory, files, dirs_exist_ok=True)
            summary = json.loads((files / 'trial.json').read_text())
            outcomes[trial.key] = Outcome(trial, files=files, summary=summary)
    return [outcomes[t.key] for t in spec.trials if t.key in outcomes]


def _trial_key(trial: Any) -> str:
    return trial.config['trial']


def _error_text(error: BaseException) -> str:
    """The trial's own exception, not Ray's wrapper around it."""
    cause = getattr(error, 'cause', None) or error
    return f'{type(cause).__name__}: {cause}'.strip()


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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split('Usage::')[1])
    parser.add_argument('spec', nargs='?', help='a YAML spec file (else the flags below)')
    parser.add_argument('--agents', help=f'comma-separated: {", ".join(BASELINES + LEARNERS)}')
    parser.add_argument('--envs', help='comma-separated GrowSpace ids')
    parser.add_argument('--seeds', default='1', help='a count (0..n-1) or a comma list')
    parser.add_argument('--steps', type=int, help='training steps (learners)')
    parser.add_argument('--episodes', type=int, default=50, help='evaluation episodes per trial')
    parser.add_argument('--eval-seed', type=int, default=10_000, help='first evaluation seed')
    parser.add_argument('--name', help='experiment name (default: the spec file name)')
    parser.add_argument('--out', help='results folder (default runs/sweeps/<name>)')
    parser.add_argument('--storage', help="Ray Tune's storage: a folder every node of a "
                                          'cluster sees, or a URI (default: OUT)')
    parser.add_argument('--address', help='a Ray cluster to use (default: $RAY_ADDRESS, else '
                                          'a local instance on 127.0.0.1)')
    parser.add_argument('--workers', type=int, help='trials at once (default: all CPUs)')
    parser.add_argument('--cpus-per-trial', type=float, default=1.0)
    parser.add_argument('--gpus-per-trial', type=float, default=0.0)
    parser.add_argument('--retry-errored', action='store_true',
                        help='on resume, run failed trials again')
    parser.add_argument('--fresh-processes', action='store_true',
                        help='run every trial in a new worker process (slower)')
    parser.add_argument('--no-plots', action='store_true')
    parser.add_argument('--quiet', action='store_true', help="no Ray Tune status tables")
    args = parser.parse_args(argv)
    if args.workers is not None and args.workers < 1:
        parser.error(f'--workers must be >= 1, got {args.workers}')
    try:
        if args.spec:
            if args.agents or args.envs:
                parser.error('give a spec file or --agents/--envs, not both')
            spec = load_spec(args.spec)
            if args.name:
                spec = Spec(args.name, spec.episodes, spec.eval_seed, spec.trials)
        elif args.agents and args.envs:
            spec = flags_spec(args)
        else:
            parser.error('give a spec file, or --agents and --envs')
        out = Path(args.out or Path('runs') / 'sweeps' / spec.name)
        start = time.perf_counter()
        connect(args.address, args.workers)
        outcomes = run_sweep(spec, out, args.storage, args.workers, args.cpus_per_trial,
                             args.gpus_per_trial, args.retry_errored, 0 if args.quiet else 1,
                             not args.fresh_processes)
    except SpecError as error:
        parser.error(str(error))
    rows = summarise(outcomes, out, plots=not args.no_plots)
    failed = [o for o in outcomes if o.error]
    print(f'\n{spec.name}: {len(outcomes) - len(failed)} of {len(spec.trials)} trials finished, '
          f'{len(failed)} failed, {time.perf_counter() - start:.1f} s; results in {out}\n')
    print(evaluate_policies.markdown(rows))
    for o in failed:
        print(f'trial {o.trial.key} failed: {o.error}', file=sys.stderr)
    if len(outcomes) < len(spec.trials):
        print(f'Interrupted: {len(spec.trials) - len(outcomes)} trials did not finish; run the '
              'same command again to resume.', file=sys.stderr)
        return 130
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
