"""Running trials on Ray Tune: one trial = one agent, env id and seed; resume, loopback."""

from __future__ import annotations

import contextlib
import csv
import json
import os
import pickle
import shutil
import socket
import stat
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from datetime import datetime, UTC
from pathlib import Path
from typing import Any

import numpy as np

from growspace_sim.agents import evaluation
from growspace_sim.learn import evaluate_policies
from growspace_sim.sweep import cluster
from growspace_sim.sweep.spec import BASELINES, Spec, SpecError, Trial


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


@dataclass(frozen=True)
class Outcome:
    """A finished (or failed) trial as the experiment sees it."""

    trial: Trial
    error: str = ''             # 'ExceptionType: message' when the trial raised
    files: Path | None = None   # the trial's files (a copy of its Ray checkpoint)
    summary: dict = field(default_factory=dict)  # trial.json


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
        played = evaluation.play_agent(eval_env, trial.agent, trial.episodes,
                                       trial.eval_seed, trial.eval_seed + trial.seed,
                                       trial.env_kwargs)
        rewards, success, label, steps = played.rewards, played.success, trial.agent, 0
    else:
        rewards, eval_env, label, steps = _train_and_evaluate(trial, out / 'run')
    returns = evaluation.episode_returns(rewards)
    mean, se = evaluation.mean_se(returns)
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
                   started=datetime.fromtimestamp(started, UTC).isoformat())
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


def connect(address: str | None, workers: int | None) -> Any | None:
    """Connect to a Ray cluster, or start a local instance bound to 127.0.0.1.

    A local instance keeps its session folders (logs, sockets) in ``private_temp_dir()``, not
    in the shared ``/tmp/ray``. Call ``disconnect()`` when done: it stops a local instance
    completely (Ray's agents included), where relying on the end of the process would leave
    them behind if that end is a kill.

    Args:
        address: A cluster's address (``ray start --head`` prints it); ``None`` reads
            ``RAY_ADDRESS`` and, without it, starts a local instance with no dashboard. A
            cluster's trials import the ``growspace_sim`` this process imported, which Ray
            copies to each node (``py_modules``); its nodes need the same venv, not this
            workspace. A cluster with token authentication needs ``RAY_AUTH_MODE=token`` and
            its token here (``~/.ray/auth_token``, ``RAY_AUTH_TOKEN_PATH`` or
            ``RAY_AUTH_TOKEN``); without one, or with one the cluster refuses, this fails at
            once (``sweep.cluster``).
        workers: CPUs of the local instance (default: all cores); unused for a cluster.

    Returns:
        The ``ray.init`` context of the Ray this call started or joined (a local instance's
        session folder is ``context.address_info['session_dir']``); None if Ray was already
        initialised in this process (then it is not this caller's to disconnect).

    Raises:
        ConnectionError: Nothing answers at the cluster's address, this machine has no token
            for a token cluster, or Ray could not join it (e.g. it refused the token); the
            message is one line.
        RuntimeError: A local instance would not stay on loopback (``ray`` was imported
            before this call; see the comment below).
    """
    os.environ['RAY_USAGE_STATS_ENABLED'] = '0'  # Ray's usage report would leave the machine
    address = address or os.environ.get('RAY_ADDRESS')
    if address:
        cluster.check_token(address)
        _check_answers(address)
    else:
        # On Linux, Ray 2.60 swaps a loopback node address for the machine's outward one (and
        # its servers then listen on every interface) unless multi-node clusters are disabled,
        # Ray's switch for Windows and macOS, read when ray is first imported. A local
        # instance is no cluster: with the switch off, every Ray process listens on and talks
        # to 127.0.0.1 only (the Ray processes inherit the variable).
        os.environ['RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER'] = '0'
    import ray  # noqa: PLC0415
    if ray.is_initialized():
        return None
    if address:
        # The trials run this package on every node: ship the driver's copy (Ray caches it by
        # content) so that the other machines need only the venv, and run the same code.
        import growspace_sim  # noqa: PLC0415
        return cluster.join(address, lambda: ray.init(
            address=address, log_to_driver=False,
            runtime_env={'py_modules': [growspace_sim], 'excludes': ['__pycache__']}))
    if ray.util.get_node_ip_address() != LOOPBACK:
        raise RuntimeError('ray was imported before growspace_sim.sweep.connect(), so a local '
                           'Ray would not stay on 127.0.0.1; set '
                           'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0 before importing ray.')
    with cluster.environ(LOCAL_ONLY_ENV):
        return ray.init(address='local', num_cpus=workers, include_dashboard=False,
                        _node_ip_address=LOOPBACK, _temp_dir=private_temp_dir(),
                        log_to_driver=False)


def _check_answers(address: str, timeout: float = 10.0) -> None:
    """Fail in seconds where Ray would not: nothing accepts a connection at ``host:port``.

    Ray 2.60 keeps retrying such an address for over 12 minutes (measured), with a warning
    every few seconds. Other forms (``auto``, ``ray://...``) are left to Ray.
    """
    host, _, port = address.rpartition(':')
    if '://' in address or not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip('[]'), int(port)), timeout=timeout).close()
    except OSError as error:
        raise ConnectionError(
            f'nothing answers at {address} ({error.strerror or error}): is `ray start --head '
            f'--port={port}` running there, and the port open to this machine?') from None


def disconnect() -> None:
    """Leave Ray: a local instance ``connect`` started stops, every process of it."""
    import ray  # noqa: PLC0415
    ray.shutdown()


def private_temp_dir() -> str:
    """Where a local Ray keeps its sessions: ``ray/`` in a folder only this user can enter.

    Ray makes its temporary folder and every session folder in it world-writable (mode 0777,
    so that the users of one machine can share ``/tmp/ray``). Inside a parent of mode 0700
    nobody else can read their logs or put files among their sockets. A parent of that name
    owned by someone else, or opened up to others, is not used: a fresh one is made instead.
    """
    parent = Path(tempfile.gettempdir()) / f'growspace-ray-{os.getuid()}'
    with contextlib.suppress(FileExistsError):
        parent.mkdir(mode=0o700)
    info = parent.lstat()
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid() or info.st_mode & 0o077:
        parent = Path(tempfile.mkdtemp(prefix='growspace-ray-'))
    return str(parent / 'ray')


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
    if '://' not in path:  # a local experiment: Tune may have left its state cut short
        _set_aside_if_unreadable(Path(path), len(by_key))
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
        # A trial whose worker could not even start (e.g. a node without a dependency) never
        # reported, so it has no config; its folder is named by its key (_trial_key).
        trial = by_key[result.config['trial'] if result.config else Path(result.path).name]
        if result.error is not None:
            outcomes[trial.key] = Outcome(trial, error=_error_text(result.error))
        elif result.checkpoint is not None:
            files = out / 'trials' / trial.key
            with result.checkpoint.as_directory() as directory:
                shutil.copytree(directory, files, dirs_exist_ok=True)
            summary = json.loads((files / 'trial.json').read_text())
            outcomes[trial.key] = Outcome(trial, files=files, summary=summary)
    return [outcomes[t.key] for t in spec.trials if t.key in outcomes]


def _set_aside_if_unreadable(path: Path, trials: int) -> None:
    """Rename a local Tune experiment that Tune could not resume, and say so.

    Tune rewrites its state at every checkpoint: ``experiment_state-<session>.json`` (which
    trials finished) and its search algorithm's ``basic-variant-state-<session>.json`` (a
    pickle), one after the other. A kill can leave one cut short (one kill in seven in
    tests/sim/test_sweep.py, which has Tune write them at every step): Tune then logs a traceback
    and quietly runs every trial again, beside the old ones. A kill between the two writes can
    leave a trial running in the search state that the experiment state has finished: Ray 2.60
    then waits for it for ever with ``--workers`` set (the search algorithm's concurrency limit
    stays full). Starting over is the only way from either, so do it in the open and keep the
    old run's files. The files are read as Tune itself reads them (Ray is pinned); a shape
    this does not know is left to Tune.
    """
    why = _why_unresumable(path)
    if not why:
        return
    aside = path.with_name(f'{path.name}-unreadable-{time.strftime("%Y%m%d-%H%M%S")}')
    path.rename(aside)
    print(f'{why}: the sweep was killed while Ray Tune wrote its state, so Tune cannot resume '
          f'it. All {trials} trials run again (each is seeded: the same results); the old run '
          f'is kept in {aside}.', file=sys.stderr)


def _why_unresumable(path: Path) -> str:
    """Why Tune could not resume the experiment in ``path`` ('' if it can, as far as we see)."""
    def newest(pattern: str) -> Path | None:
        files = sorted(path.glob(pattern))  # named by session start time
        return files[-1] if files else None

    state, search = newest('experiment_state-*.json'), newest('basic-variant-state-*.json')
    finished: set[str] = set()
    if state is not None:
        try:
            for data in json.loads(state.read_text()).get('trial_data', []):
                trial = json.loads(data[0]) if isinstance(data[0], str) else data[0]
                if trial.get('status') in ('TERMINATED', 'ERROR'):
                    finished.add(trial.get('trial_id'))
        except (ValueError, TypeError, AttributeError, IndexError):
            return f'{state} is cut short'
    if search is None:
        return ''
    try:
        searcher = pickle.loads(search.read_bytes())  # Tune's own file, as Tune reads it
    except (ValueError, EOFError, pickle.UnpicklingError):
        return f'{search} is cut short'
    live = searcher.get('_live_trials', ()) if isinstance(searcher, dict) else ()
    stale = finished & set(live)
    if stale and state is not None:
        return f'{search} still runs trial(s) {", ".join(sorted(stale))} that {state.name} ' \
            'has finished'
    return ''


def _trial_key(trial: Any) -> str:
    return trial.config['trial']


def _error_text(error: BaseException) -> str:
    """The trial's own exception, not Ray's wrapper around it."""
    cause = getattr(error, 'cause', None) or error
    return f'{type(cause).__name__}: {cause}'.strip()
