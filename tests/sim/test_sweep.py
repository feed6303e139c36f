"""growspace-sweep: experiments as Ray Tune trials on a local Ray bound to 127.0.0.1.

Needs ray[tune] (requirements-sweep.txt); skipped without it. Evaluation trials (random and
oracle agents) need no torch; the one training sweep is skipped without requirements-learn.txt.
One local Ray instance with 2 CPUs serves the in-process sweeps; the interrupted sweep runs in
a child process that is killed with SIGKILL.
"""

from __future__ import annotations

import contextlib
import csv
import importlib.util
import json
import os
import pickle
import signal
import socket
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import pytest
import yaml
from conftest import child_env

from growspace_sim import sweep
from growspace_sim.sweep import trials as trials_module

# Not imported here: sweep.connect() must set Ray's environment before ray's first import.

from growspace_sim.tools import evaluate

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

if importlib.util.find_spec('ray') is None or importlib.util.find_spec('pandas') is None:
    pytest.skip('ray[tune] is not installed (requirements-sweep.txt)', allow_module_level=True)


@pytest.fixture(scope='module')
def local_ray():
    """One local Ray instance (2 CPUs) for the module, started the way growspace-sweep does."""
    with pytest.MonkeyPatch.context() as patch:
        for name in ('RAY_ADDRESS', 'RAY_USAGE_STATS_ENABLED',
                     'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER'):
            patch.delenv(name, raising=False)
        assert sweep.connect(None, workers=2) is not None
        import ray  # noqa: PLC0415
        yield ray
        sweep.disconnect()


def _write_spec(path: Path, runs: list[dict], episodes: int = 4, eval_seed: int = 0) -> Path:
    path.write_text(yaml.safe_dump({'name': path.stem, 'episodes': episodes,
                                    'eval_seed': eval_seed, 'runs': runs}))
    return path


def _read_csv(path: Path) -> list[dict]:
    with open(path, newline='') as f:
        return list(csv.DictReader(f))


def test_evaluation_sweep_on_two_workers_equals_sequential_growspace_eval(tmp_path, local_ray):
    nodes = local_ray.nodes()
    assert [n['NodeManagerAddress'] for n in nodes] == ['127.0.0.1']
    assert local_ray.cluster_resources()['CPU'] == 2

    def proxies() -> list[str | None]:
        return [os.environ.get(name) for name in sweep.LOCAL_ONLY_ENV]

    # Ray's processes send HTTP to a closed loopback port; the driver's environment is restored.
    assert local_ray.get(local_ray.remote(proxies).remote()) == list(sweep.LOCAL_ONLY_ENV.values())
    assert os.environ.get('https_proxy') != sweep.LOCAL_ONLY_ENV['https_proxy']
    spec = _write_spec(tmp_path / 'equal.yaml', [
        {'agents': ['random', 'oracle'],
         'envs': ['GrowSpace/Control-Hard-v0', 'GrowSpace/Fairness-Easy-v0']}],
        episodes=5, eval_seed=3)

    assert sweep.main([str(spec), '--out', str(tmp_path / 'out'), '--workers', '2',
                       '--quiet']) == 0

    assert evaluate.main(['--episodes', '5', '--seed', '3', '--challenges', 'control,fairness',
                          '--settings', 'hard,easy', '--csv', str(tmp_path / 'eval.csv')]) == 0
    expected = {}
    for row in _read_csv(tmp_path / 'eval.csv'):
        env = f'GrowSpace/{"Control" if row["challenge"] == "control" else "Fairness"}-' \
              f'{row["setting"].capitalize()}-v0'
        for agent in ('random', 'oracle'):
            expected[env, agent] = (float(row[f'{agent}_mean']), float(row[f'{agent}_se']))
    swept = {(r['env'], r['agent']): (float(r['mean']), float(r['se']))
             for r in _read_csv(tmp_path / 'out' / 'results.csv')}
    assert len(swept) == 4
    assert swept == {k: v for k, v in expected.items() if k in swept}
    trials = _read_csv(tmp_path / 'out' / 'trials.csv')
    assert {t['status'] for t in trials} == {'ok'}
    assert (tmp_path / 'out' / 'rewards.png').stat().st_size > 0
    per_episode = _read_csv(tmp_path / 'out' / 'trials' / 'oracle-control-hard-s0'
                            / 'evaluation.csv')
    assert [int(r['episode_seed']) for r in per_episode] == [3, 4, 5, 6, 7]


def test_failing_trial_is_reported_with_its_error_and_the_others_finish(
        tmp_path, local_ray, capsys):
    spec = _write_spec(tmp_path / 'failing.yaml', [
        {'agents': ['random'], 'envs': ['GrowSpace/Control-Easy-v0'], 'seeds': 2},
        {'agents': ['random'], 'envs': ['GrowSpace/Control-Easy-v0'], 'label': 'dense',
         'env_kwargs': {'light_density': 0}}])

    assert sweep.main([str(spec), '--out', str(tmp_path / 'out'), '--workers', '2',
                       '--quiet', '--no-plots']) == 1

    trials = {t['key']: t for t in _read_csv(tmp_path / 'out' / 'trials.csv')}
    assert [t['status'] for t in trials.values()] == ['ok', 'ok', 'error']
    error = trials['dense-control-easy-s0']['error']
    assert error.startswith('ValueError: light_density must be in [1, 100000], got 0')
    assert f'trial dense-control-easy-s0 failed: {error}' in capsys.readouterr().err
    assert [(r['agent'], r['runs'], r['episodes'])
            for r in _read_csv(tmp_path / 'out' / 'results.csv')] == [('random', '2', '4')]


def test_sweep_killed_midway_resumes_without_rerunning_finished_trials(tmp_path, local_ray):
    n = 8
    spec = _write_spec(tmp_path / 'resume.yaml', [
        {'agents': ['random'], 'envs': ['GrowSpace/Control-Easy-v0'], 'seeds': n}],
        episodes=10)
    out = tmp_path / 'out'
    env = child_env()
    env['TUNE_GLOBAL_CHECKPOINT_S'] = '0'  # Tune saves its state at every step
    env.pop('RAY_ADDRESS', None)
    with open(tmp_path / 'killed.log', 'w') as log:
        child = subprocess.Popen(
            [sys.executable, '-m', 'growspace_sim.sweep', str(spec), '--out', str(out),
             '--workers', '1', '--quiet', '--no-plots'],
            env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            _wait_for(lambda: _finished(out), 3, child, tmp_path / 'killed.log')
            killed = time.time()
            child.send_signal(signal.SIGKILL)
            child.wait(timeout=30)
        finally:
            # The killed sweep's own Ray: its agents would outlive it for about a minute.
            assert _stop_group(child.pid) == []
    finished = _finished(out)  # one more may have finished before the signal landed
    assert 3 <= len(finished) < n, 'the sweep was not killed mid-way'
    assert all(len(runs) == 1 for runs in finished.values())
    # One trial at a time: a trial starts only after Tune saved the previous one as finished,
    # so every finished trial but the newest one is on record, unless the kill cut Tune's
    # state file short (Tune writes it at every step here): then every trial runs again.
    newest = max(finished, key=lambda k: finished[k][0]['started'])
    on_record = {k: v for k, v in finished.items() if k != newest}
    assert sweep.main([str(spec), '--out', str(out), '--workers', '2', '--quiet',
                       '--no-plots']) == 0

    after = _finished(out)
    assert len(after) == n
    # Unless the kill cut Tune's state short or between its two files: then the old run was
    # set aside whole (test_a_tune_state_..._is_set_aside) and every trial ran again.
    aside = list(tmp_path.glob('out/tune-unreadable-*'))
    if aside:
        [aside] = aside
        assert {p.name for p in aside.iterdir()} >= set(finished)
        on_record = {}
    for key, runs in on_record.items():  # still the one execution of the first sweep
        assert after[key] == runs, f'{key} ran again'
    for key in after.keys() - finished.keys():  # run by the second sweep, not a leftover
        assert [datetime.fromisoformat(r['started']).timestamp() > killed
                for r in after[key]] == [True], key
    assert {t['status'] for t in _read_csv(out / 'trials.csv')} == {'ok'}


@pytest.mark.parametrize('cut', ['experiment_state', 'basic-variant-state'])
def test_a_tune_state_cut_short_is_set_aside_and_every_trial_runs_again(
        tmp_path, local_ray, capsys, cut):
    spec = _write_spec(tmp_path / 'cut.yaml', [
        {'agents': ['random'], 'envs': ['GrowSpace/Control-Easy-v0'], 'seeds': 2}])
    out = tmp_path / 'out'
    args = [str(spec), '--out', str(out), '--workers', '2', '--quiet', '--no-plots']
    assert sweep.main(args) == 0
    first = _read_csv(out / 'trials.csv')
    state = max((out / 'tune').glob(f'{cut}-*.json'))  # Tune's search state is a pickle
    state.write_bytes(state.read_bytes()[:len(state.read_bytes()) // 2])  # a kill mid-write
    capsys.readouterr()

    assert sweep.main(args) == 0

    err = capsys.readouterr().err
    assert f'{state} is cut short' in err and 'All 2 trials run again' in err
    aside = list(tmp_path.glob('out/tune-unreadable-*'))
    assert len(aside) == 1 and (aside[0] / state.name).exists()
    assert all(len(runs) == 1 for runs in _finished(out).values()) and len(_finished(out)) == 2
    again = _read_csv(out / 'trials.csv')
    assert [(r['key'], r['status'], r['mean'], r['se']) for r in again] == \
        [(r['key'], r['status'], r['mean'], r['se']) for r in first]


def test_a_search_state_that_runs_a_finished_trial_is_set_aside(tmp_path, capsys):
    """Killed between Tune's two state files: the search algorithm still counts a trial as
    running that the experiment state has finished, and Tune 2.60 would wait for it for ever."""
    def experiment(live: set[str]) -> Path:
        path = tmp_path / f'tune-{len(live)}'
        path.mkdir()
        trials = [[json.dumps({'trial_id': f'a_{i:05d}', 'status': 'TERMINATED'}), '{}']
                  for i in range(2)]
        (path / 'experiment_state-2026.json').write_text(json.dumps({'trial_data': trials}))
        (path / 'basic-variant-state-2026.json').write_bytes(
            pickle.dumps({'_live_trials': live, '_finished': False}))
        return path

    consistent, stale = experiment(set()), experiment({'a_00001'})
    trials_module._set_aside_if_unreadable(consistent, 2)
    trials_module._set_aside_if_unreadable(stale, 2)
    assert consistent.exists() and not stale.exists()
    assert len(list(tmp_path.glob('tune-1-unreadable-*'))) == 1
    err = capsys.readouterr().err
    assert 'still runs trial(s) a_00001 that experiment_state-2026.json has finished' in err
    assert 'All 2 trials run again' in err


def _group(pgid: int) -> list[int]:
    """The live (not zombie) processes of a process group."""
    found = []
    for stat in Path('/proc').glob('[0-9]*/stat'):
        try:
            fields = stat.read_text().rsplit(')', 1)[1].split()
        except OSError:  # gone meanwhile
            continue
        if int(fields[2]) == pgid and fields[0] not in 'ZX':
            found.append(int(stat.parent.name))
    return found


def _stop_group(pgid: int, within_s: float = 10.0) -> list[int]:
    """SIGKILL a process group we started; the pids still alive after ``within_s``."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(pgid, signal.SIGKILL)
    deadline = time.monotonic() + within_s
    while _group(pgid) and time.monotonic() < deadline:
        time.sleep(0.1)
    return _group(pgid)


PRIVATE_SESSION = """
import json, os
from growspace_sim import sweep
context = sweep.connect(None, 1)
import ray
assert ray.get(ray.remote(lambda: 7).remote()) == 7
print(json.dumps(context.address_info['session_dir']), flush=True)
sweep.disconnect()
"""


def test_a_local_ray_keeps_its_sessions_private_and_stops_completely():
    env = child_env()
    env.pop('RAY_ADDRESS', None)
    child = subprocess.Popen([sys.executable, '-c', PRIVATE_SESSION], env=env, text=True,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             start_new_session=True)
    try:
        out, err = child.communicate(timeout=120)
        assert child.returncode == 0, err[-2000:]
        # Every Ray process it started (gcs, raylet, dashboard head, agents) is gone.
        deadline = time.monotonic() + 10.0
        while _group(child.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _group(child.pid) == []
    finally:
        _stop_group(child.pid)
    session = Path(json.loads(out.strip().splitlines()[-1]))
    root = Path(sweep.private_temp_dir())
    assert session.parent == root and session.is_dir()
    # Ray opens its own folders to everyone (0777); their parent lets nobody else in.
    info = root.parent.stat()
    assert info.st_uid == os.getuid() and info.st_mode & 0o077 == 0, oct(info.st_mode)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def test_an_address_where_nothing_answers_is_one_line_at_once(tmp_path, capsys):
    port = _free_port()  # closed again: nothing listens there
    assert sweep.main(['--agents', 'oracle', '--envs', 'GrowSpace/Control-Easy-v0',
                       '--episodes', '2', '--out', str(tmp_path / 'out'), '--quiet',
                       '--address', f'127.0.0.1:{port}']) == 1
    assert capsys.readouterr().err == (
        f'growspace-sweep: error: nothing answers at 127.0.0.1:{port} (Connection refused): '
        f'is `ray start --head --port={port}` running there, and the port open to this '
        'machine?\n')


def test_a_token_cluster_from_ray_start_runs_trials_without_the_workspace(tmp_path):
    """The README's cluster recipe on one loopback node: token authentication on, and a Ray
    started without this workspace on its path (the sweep ships growspace_sim to it)."""
    ray_cli = str(Path(sys.executable).with_name('ray'))
    node_env = {name: value for name, value in child_env().items() if name != 'PYTHONPATH'}
    node_env.update(HOME=str(tmp_path), RAY_AUTH_MODE='token', RAY_USAGE_STATS_ENABLED='0',
                    RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER='0')  # every Ray server on 127.0.0.1
    assert subprocess.run([sys.executable, '-c', 'import growspace_sim'], env=node_env,
                          capture_output=True).returncode != 0  # the nodes cannot import it
    subprocess.run([ray_cli, 'get-auth-token', '--generate'], env=node_env, check=True,
                   capture_output=True)
    port, log = _free_port(), tmp_path / 'head.log'
    # Ray's socket paths must fit in 107 bytes: pytest's tmp_path is too long for them.
    temp_dir = tempfile.TemporaryDirectory(prefix='gs-ray-')
    with open(log, 'w') as out:
        head = subprocess.Popen(
            [ray_cli, 'start', '--head', '--block', f'--port={port}', '--num-cpus=1',
             '--node-ip-address=127.0.0.1', '--include-dashboard=false',
             f'--temp-dir={temp_dir.name}/ray'],
            env=node_env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 60.0
        while 'Ray runtime started' not in log.read_text():
            assert head.poll() is None and time.monotonic() < deadline, log.read_text()[-2000:]
            time.sleep(0.2)
        driver_env = dict(child_env(), HOME=str(tmp_path), RAY_AUTH_MODE='token')
        driver_env.pop('RAY_ADDRESS', None)
        run = subprocess.run(
            [sys.executable, '-m', 'growspace_sim.sweep', '--agents', 'oracle', '--envs',
             'GrowSpace/Control-Easy-v0', '--episodes', '2', '--out', str(tmp_path / 'out'),
             '--storage', str(tmp_path / 'storage'), '--quiet', '--no-plots',
             '--address', f'127.0.0.1:{port}'],
            env=driver_env, capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr[-3000:]
        [trial] = _read_csv(tmp_path / 'out' / 'trials.csv')
        assert (trial['key'], trial['status']) == ('oracle-control-easy-s0', 'ok')
        [experiment] = (tmp_path / 'storage').iterdir()  # Tune's state, in --storage
        assert list(experiment.glob('experiment_state-*.json'))
        assert (experiment / 'oracle-control-easy-s0').is_dir()
        # Without the token, or with another: one line, and no Ray retries (about 20 s of
        # warnings, a traceback without a token, before sweep.cluster).
        stranger = tmp_path / 'stranger'
        (stranger / '.ray').mkdir(parents=True)
        for token, said in ((None, 'this machine has no Ray token for the cluster'),
                            ('not-the-heads-token', "refused this machine's token")):
            if token:
                (stranger / '.ray' / 'auth_token').write_text(token)
            refused = subprocess.run(
                [sys.executable, '-m', 'growspace_sim.sweep', '--agents', 'oracle', '--envs',
                 'GrowSpace/Control-Easy-v0', '--out', str(tmp_path / 'out2'), '--quiet',
                 '--address', f'127.0.0.1:{port}'], env=dict(driver_env, HOME=str(stranger)),
                capture_output=True, text=True, timeout=300)
            assert refused.returncode == 1, refused.stderr[-3000:]
            assert refused.stderr.count('\n') == 1 and said in refused.stderr, refused.stderr
            assert refused.stderr.startswith('growspace-sweep: error: '), refused.stderr
    finally:
        head.terminate()  # `ray start --block` stops its node's processes on SIGTERM
        with contextlib.suppress(subprocess.TimeoutExpired):
            head.wait(timeout=60)
        deadline = time.monotonic() + 10.0
        while _group(head.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        left = _group(head.pid)
        _stop_group(head.pid)
        temp_dir.cleanup()
    assert left == [], 'Ray processes outlived ray start --block'


def test_the_token_is_looked_for_where_ray_looks(tmp_path, monkeypatch):
    """Ray's documented order: RAY_AUTH_TOKEN, else the file RAY_AUTH_TOKEN_PATH names (and
    no other), else ~/.ray/auth_token."""
    from growspace_sim.sweep import cluster  # noqa: PLC0415

    monkeypatch.setenv('HOME', str(tmp_path))
    for name in ('RAY_AUTH_TOKEN', 'RAY_AUTH_TOKEN_PATH'):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv('RAY_AUTH_MODE', 'token')
    assert cluster.token_source() is None
    with pytest.raises(ConnectionError, match='^RAY_AUTH_MODE=token but this machine has no Ray '
                                              'token for the cluster at h:1: copy'):
        cluster.check_token('h:1')
    (tmp_path / '.ray').mkdir()
    (tmp_path / '.ray' / 'auth_token').write_text('abc\n')
    assert cluster.token_source() == str(tmp_path / '.ray' / 'auth_token')
    empty = tmp_path / 'empty'
    empty.write_text('')
    monkeypatch.setenv('RAY_AUTH_TOKEN_PATH', str(empty))
    with pytest.raises(ConnectionError, match=f'^RAY_AUTH_TOKEN_PATH={empty} is empty'):
        cluster.check_token('h:1')
    monkeypatch.setenv('RAY_AUTH_TOKEN', 'xyz')
    assert cluster.token_source() == 'RAY_AUTH_TOKEN'
    monkeypatch.setenv('RAY_AUTH_MODE', 'disabled')
    monkeypatch.setenv('RAY_AUTH_TOKEN_PATH', str(tmp_path / 'missing'))
    cluster.check_token('h:1')  # no token mode: nothing to check


def _finished(out: Path) -> dict[str, list[dict]]:
    """Per trial key, the trial.json of each checkpoint Tune wrote: one per execution."""
    found: dict[str, list[dict]] = {}
    for path in sorted((out / 'tune').glob('*/checkpoint_*/trial.json')):
        try:
            found.setdefault(path.parent.parent.name, []).append(json.loads(path.read_text()))
        except ValueError:  # being written
            continue
    return found


def _wait_for(check, count: int, child: subprocess.Popen, log: Path,
              timeout: float = 180.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if len(check()) >= count:
            return
        if child.poll() is not None:
            pytest.fail(f'the sweep exited early ({child.returncode}): '
                        f'{log.read_text()[-2000:]}')
        time.sleep(0.1)
    child.kill()
    pytest.fail(f'fewer than {count} trials finished in {timeout} s')


@pytest.mark.parametrize('change, message', [
    ({'colour': 'red'}, 'spec: unknown key(s) colour; allowed: name, episodes'),
    ({'episodes': 1}, 'episodes must be >= 2, got 1.'),
    ({'runs': [{'agents': ['random'], 'envs': ['GrowSpace/Nope-v0']}]},
     "runs[0].envs: unknown 'GrowSpace/Nope-v0'; allowed: GrowSpace/Control-Easy-v0"),
    ({'runs': [{'agents': ['greedy'], 'envs': ['GrowSpace/Control-Easy-v0']}]},
     "runs[0].agents: unknown 'greedy'; allowed: random, oracle, ppo"),
    ({'runs': [{'agents': ['random'], 'envs': ['GrowSpace/Control-Easy-v0'], 'seeds': -1}]},
     'runs[0].seeds must be >= 1, got -1.'),
    ({'runs': [{'agents': ['random'], 'envs': ['GrowSpace/Control-Easy-v0'], 'steps': 10}]},
     'runs[0]: steps only apply to learners'),
    ({'runs': [{'agents': ['oracle'], 'envs': ['GrowSpace/ControlContinuous-Easy-v0']}]},
     'runs[0]: the oracle acts through discrete actions'),
    ({'runs': [{'agents': ['random'], 'envs': ['GrowSpace/Control-Easy-v0']},
               {'agents': ['random'], 'envs': ['GrowSpace/Control-Easy-v0'], 'seeds': [0]}]},
     'runs[1]: trial random-control-easy-s0 is also in runs[0]'),
])
def test_bad_spec_names_the_field_the_value_and_what_is_allowed(change, message):
    data = {'name': 'bad', 'runs': [{'agents': ['random'],
                                     'envs': ['GrowSpace/Control-Easy-v0']}], **change}
    with pytest.raises(sweep.SpecError) as error:
        sweep.parse_spec(data)
    assert message in str(error.value)


def test_shipped_specs_expand_to_their_trials():
    root = Path(__file__).resolve().parents[2] / 'config' / 'sweeps'
    reference = sweep.load_spec(root / 'reference_agents.yaml')
    assert len(reference.trials) == 8 * 5 + 8  # the oracle is deterministic: one seed
    if importlib.util.find_spec('stable_baselines3') is None:
        with pytest.raises(sweep.SpecError, match='need the learn extra'):
            sweep.load_spec(root / 'case_studies.yaml')
        return
    cases = sweep.load_spec(root / 'case_studies.yaml')
    learners = [t for t in cases.trials if t.agent in sweep.LEARNERS]
    assert len(learners) == 3 + 8 * 2 + 2 + 3
    curriculum = [t for t in learners if t.env == 'GrowSpace/Shape-Curriculum-v0']
    assert [(t.n_envs, t.hp, t.env_kwargs) for t in curriculum] == \
        [(8, {'n_steps': 256, 'batch_size': 64}, {'episodes_per_stage': 12})] * 2


def test_training_sweep_trains_evaluates_and_plots(tmp_path, local_ray):
    pytest.importorskip('stable_baselines3', reason='needs requirements-learn.txt')
    from growspace_sim.learn import train  # noqa: PLC0415
    assert sorted(sweep.LEARNERS) == sorted(train.ALGOS)
    spec = _write_spec(tmp_path / 'train.yaml', [
        {'agents': ['ppo'], 'envs': ['GrowSpace/Control-Hard-v0'], 'seeds': 2, 'steps': 256,
         'n_envs': 2, 'hp': {'n_steps': 64, 'batch_size': 32, 'n_epochs': 1}},
        {'agents': ['random'], 'envs': ['GrowSpace/Control-Hard-v0']}], episodes=3)

    assert sweep.main([str(spec), '--out', str(tmp_path / 'out'), '--workers', '2',
                       '--quiet']) == 0

    rows = {r['agent']: r for r in _read_csv(tmp_path / 'out' / 'results.csv')}
    assert (rows['ppo']['runs'], rows['ppo']['steps']) == ('2', '256')
    run = tmp_path / 'out' / 'trials' / 'ppo-control-hard-s1' / 'run'
    assert json.loads((run / 'run.json').read_text())['seed'] == 1
    assert (run / 'model.zip').exists() and (run / 'episodes.csv').exists()
    assert (tmp_path / 'out' / 'training.png').stat().st_size > 0
