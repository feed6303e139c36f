"""Console programs answer a missing extra or a closed pipe with a sentence, not a traceback."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from growspace_sim import learn


def _hide(monkeypatch: pytest.MonkeyPatch, *names: str) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, 'find_spec',
                        lambda name, *a: None if name in names else real(name, *a))


def test_growspace_train_without_torch_names_the_extra(monkeypatch, capsys) -> None:
    _hide(monkeypatch, 'torch', 'stable_baselines3')
    assert learn.train_main(['--help']) == 2
    err = capsys.readouterr().err
    assert err.strip() == ('growspace-train: needs the learn extra (torch, stable_baselines3 not '
                           'installed): pip install -r requirements-learn.txt')


def test_growspace_compare_of_a_run_without_torch_names_the_extra(monkeypatch, capsys,
                                                                  tmp_path: Path) -> None:
    from growspace_sim.learn import evaluate_policies

    _hide(monkeypatch, 'torch', 'stable_baselines3')
    (tmp_path / 'run.json').write_text(json.dumps({'env': 'GrowSpace/Control-Easy-v0'}))
    assert evaluate_policies.main(['--run', str(tmp_path)]) == 2
    assert 'needs the learn extra (torch, stable_baselines3 not installed)' in \
        capsys.readouterr().err


def test_gcode_into_a_closed_pipe_stops_quietly() -> None:
    # `growspace-gantry-gcode BAG | head`: the reader leaves after a few lines.
    import subprocess
    import sys

    bag = Path(__file__).resolve().parents[2] / 'bags' / 'oracle_control_easy.mcap'
    if not bag.exists():
        pytest.skip('no sample bags')
    writer = subprocess.Popen([sys.executable, '-m', 'growspace_gantry.gcode', str(bag)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    writer.stdout.readline()
    writer.stdout.close()  # as `head -1` does
    _, err = writer.communicate(timeout=60)
    assert writer.returncode == 0 and b'Traceback' not in err and b'BrokenPipe' not in err, err


# --- Every console script: a bad argument is one line on stderr, exit 2, before any work ---
#
# Each row: (console script, its arguments, what the one line must hold: the argument and the
# value). Placeholders: {file} an existing plain file, {bag} a recording, {dir} an existing
# folder. The scripts' main() runs in this process with the arguments (what the console
# script runs); the nodes' parameter values are checked by a node that starts, in a child.

ROOT = Path(__file__).resolve().parents[2]
BAG = ROOT / 'bags' / 'oracle_control_easy.mcap'
MISSING = '/nonexistent/dir'

BAD_ARGUMENTS = [
    ('growspace-eval', ['--episodes', '1'], 'argument --episodes: 1 is not allowed'),
    ('growspace-eval', ['--episodes', 'x'], "argument --episodes: 'x' is not allowed"),
    ('growspace-eval', ['--episodes', '2', '--seed', '-4'], 'argument --seed: -4 is not allowed'),
    ('growspace-eval', ['--challenges', 'control,nosuch'],
     '--challenges: challenge must be one of'),
    ('growspace-eval', ['--challenges', 'control', '--settings', 'nope'],
     "--settings: control has no setting ['nope']"),
    ('growspace-eval', ['--csv', f'{MISSING}/out.csv'], f"argument --csv: '{MISSING}/out.csv'"),
    ('growspace-bench', ['--episodes', '-5'], 'argument --episodes: -5 is not allowed'),
    ('growspace-bench', ['--repeats', '0'], 'argument --repeats: 0 is not allowed'),
    ('growspace-bench', ['--seed', '-1'], 'argument --seed: -1 is not allowed'),
    ('growspace-bench', ['--challenges', 'nosuch', '--episodes', '1', '--repeats', '1'],
     'argument --challenges: challenge must be one of'),
    ('growspace-bench', ['--num-envs', '1,x'], "argument --num-envs: 'x' is not allowed"),
    ('growspace-bench', ['--num-envs', '0'], 'argument --num-envs: 0 is not allowed'),
    ('growspace-demo', ['--seed', '-1'], 'argument --seed: -1 is not allowed'),
    ('growspace-demo', ['--setting', 'nope'], "argument --setting: invalid choice: 'nope'"),
    ('growspace-demo', ['--out', '{file}'], "argument --out: '{file}' is a file"),
    ('growspace-demo', ['--out', '{file}/sub'],
     "argument --out: '{file}/sub': '{file}' is a file"),
    ('growspace-record', ['run', 'x.mcap', '--episodes', '-1'],
     'argument --episodes: -1 is not allowed'),
    ('growspace-record', ['run', 'x.mcap', '--episodes', '0'],
     'argument --episodes: 0 is not allowed'),
    ('growspace-record', ['run', 'x.mcap', '--seed', '-1'], 'argument --seed: -1 is not allowed'),
    ('growspace-record', ['run', 'x.mcap', '--rate-hz', '0'], 'argument --rate-hz: 0 is not'),
    ('growspace-record', ['run', 'x.mcap', '--rate-hz', 'nan'], 'argument --rate-hz: nan is not'),
    ('growspace-record', ['run', 'x.mcap', '--agent', 'nope'], "--agent: invalid choice: 'nope'"),
    ('growspace-record', ['run', 'x.mcap', '--challenge', 'nosuch'],
     'argument --challenge: challenge must be one of'),
    ('growspace-record', ['run', 'x.mcap', '--setting', 'nope'],
     "argument --setting: setting must be one of ('easy', 'hard'), got 'nope'"),
    ('growspace-record', ['run', 'x.mcap', '--namespace', 'bad//ns'],
     "argument --namespace: 'bad//ns' is not allowed"),
    ('growspace-record', ['run', f'{MISSING}/x.mcap'], f"argument out: '{MISSING}/x.mcap'"),
    ('growspace-record', ['subscribe', 'x.mcap', '--duration', '0'],
     'argument --duration: 0 is not allowed'),
    ('growspace-record', ['subscribe', 'x.mcap', '--domain-id', '300'],
     'argument --domain-id: 300 is not allowed; expected an integer in [0, 232]'),
    ('growspace-record', ['subscribe', 'x.mcap', '--namespace', 'a b'],
     "argument --namespace: 'a b' is not allowed"),
    ('growspace-replay', ['info', '{bag}', '--namespace', '1chamber'],
     "argument --namespace: '1chamber' is not allowed"),
    ('growspace-replay', ['compare', '{bag}', '{bag}', '--namespace-b', 'a//b'],
     "argument --namespace-b: 'a//b' is not allowed"),
    ('growspace-camera', ['export', '{bag}', 'seen', '--namespace', 'a b'],
     "argument --namespace: 'a b' is not allowed"),
    ('growspace-replay', ['info', 'nosuch.mcap'],
     "argument bag: 'nosuch.mcap': no such file or folder"),
    ('growspace-replay', ['info', '{dir}'], '{dir} is a directory without recording files'),
    ('growspace-replay', ['check', 'nosuch.mcap'], "argument bag: 'nosuch.mcap'"),
    ('growspace-replay', ['check', '{file}'], 'is not an MCAP file'),  # and no progress bar
    ('growspace-replay', ['check', '{bag}', '--digit-source', 'nope'],
     "argument --digit-source: invalid choice: 'nope'"),
    ('growspace-replay', ['export', '{bag}', f'{MISSING}/a.gif'],
     f"argument out: '{MISSING}/a.gif': the folder '{MISSING}' does not exist"),
    ('growspace-replay', ['export', '{bag}', 'a.gif', '--fps', '0'], 'argument --fps: 0 is not'),
    ('growspace-replay', ['export', '{bag}', 'a.gif', '--scale', '0'], 'argument --scale: 0 is'),
    ('growspace-replay', ['export', '{bag}', 'a.gif', '--scale', '1.5'],
     "argument --scale: '1.5' is not allowed"),
    ('growspace-replay', ['export', '{bag}', 'a.mcap', '--view', '--view-size', '8'],
     'argument --view-size: 8 is not allowed'),
    ('growspace-replay', ['export', '{bag}', 'a.gif', '--episode', '99'],
     'episode 99 does not exist'),
    ('growspace-replay', ['export', '{bag}', 'a.gif', '--episode', 'last'],
     "argument --episode: invalid int value: 'last'"),
    ('growspace-replay', ['play', '{bag}', '--domain-id', '-1'],
     'argument --domain-id: -1 is not allowed'),
    ('growspace-replay', ['play', '{bag}', '--rate', '0'], 'argument --rate: 0 is not allowed'),
    ('growspace-replay', ['play', '{bag}', '--wait', '-1'], 'argument --wait: -1 is not allowed'),
    ('growspace-replay', ['play', '{bag}', '--step-period', '-1'],
     'argument --step-period: -1 is not allowed'),
    ('growspace-replay', ['play', '{bag}', '--step-period', '0', '--start-step', '0'],
     'argument --start-step: 0 is not allowed'),
    ('growspace-replay', ['play', '{bag}', '--step-period', '0', '--stop-step', '-2'],
     'argument --stop-step: -2 is not allowed'),
    ('growspace-replay', ['play', '{bag}', '--step-period', '0', '--step-timeout', '0'],
     'argument --step-timeout: 0 is not allowed'),
    ('growspace-replay', ['play', '{bag}', '--episode', '0'], '--episode need(s) --step-period'),
    ('growspace-replay', ['play', 'nosuch.mcap'], "argument bag: 'nosuch.mcap'"),
    ('growspace-replay', ['compare', '{bag}', '{bag}', '--tolerance-mm', '-1'],
     'argument --tolerance-mm: -1 is not allowed; expected a number >= 0'),
    ('growspace-replay', ['compare', '{bag}', 'nosuch.mcap'], "argument b: 'nosuch.mcap'"),
    ('growspace-replay', ['recover', 'nosuch.mcap', 'out.mcap'], "argument bag: 'nosuch.mcap'"),
    ('growspace-replay', ['recover', '{bag}', f'{MISSING}/o.mcap'],
     f"argument out: '{MISSING}/o.mcap'"),
    ('growspace-gantry-gcode', ['{bag}', '--lamp-power', '5'],
     'argument --lamp-power: 5 is not allowed; expected a number in [0, 1]'),
    ('growspace-gantry-gcode', ['{bag}', '--lamp-power', '-1'], 'argument --lamp-power: -1 is'),
    ('growspace-gantry-gcode', ['{bag}', '--lamp-power', 'nan'], 'argument --lamp-power: nan'),
    ('growspace-gantry-gcode', ['{bag}', '--episode', '9'], '--episode 9: the recording has 1'),
    ('growspace-gantry-gcode', ['{bag}', '--episode', 'x'], 'argument --episode: invalid int'),
    ('growspace-gantry-gcode', ['nosuch.mcap'], "argument bag: 'nosuch.mcap'"),
    ('growspace-gantry-gcode', ['{bag}', '--calibration', 'nosuch.yaml'],
     "argument --calibration: 'nosuch.yaml'"),
    ('growspace-camera', ['markers', f'{MISSING}/s.svg'],
     f"argument sheet: '{MISSING}/s.svg': the folder '{MISSING}' does not exist"),
    ('growspace-camera', ['markers', 's.svg', '--markers', 'nosuch.yaml'],
     "argument --markers: 'nosuch.yaml'"),
    ('growspace-camera', ['twin', 'out', '--steps', '-1'], 'argument --steps: -1 is not'),
    ('growspace-camera', ['twin', 'out', '--seed', '-1'], 'argument --seed: -1 is not'),
    ('growspace-camera', ['twin', '{file}'], "argument out: '{file}' is a file"),
    ('growspace-camera', ['twin', 'out', '--challenge', 'nosuch'],
     'argument --challenge: challenge must be one of'),
    ('growspace-camera', ['measure', '{file}', '--setting', 'nope'],
     "argument --setting: setting must be one of ('easy', 'hard'), got 'nope'"),
    ('growspace-camera', ['twin', 'out', '--markers', '{file}'],
     'argument --markers: {file}: needs exactly the keys'),
    ('growspace-camera', ['measure', 'nosuch.jpg'], "argument photos: 'nosuch.jpg'"),
    ('growspace-camera', ['measure', '{file}', '--target-x', 'inf'],
     'argument --target-x: inf is not allowed'),
    ('growspace-camera', ['measure', '{file}', '--overlay', '{file}'],
     "argument --overlay: '{file}' is a file"),
    ('growspace-camera', ['measure', '{file}', '--lens', 'nosuch.yaml'],
     "argument --lens: 'nosuch.yaml'"),
    ('growspace-camera', ['measure', '{file}', '--lens', '{file}'],
     "argument --lens: lens = '{file}': needs a mapping of image_width"),
    ('growspace-camera', ['resegment', 'nosuch.mcap', 'o.mcap'], "argument bag: 'nosuch.mcap'"),
    ('growspace-camera', ['resegment', '{bag}', f'{MISSING}/o.mcap'],
     f"argument out: '{MISSING}/o.mcap'"),
    ('growspace-camera', ['resegment', '{bag}', 'o.mcap', '--params', 'nosuch.yaml'],
     "argument --params: 'nosuch.yaml'"),
    ('growspace-camera', ['export', '{bag}', 'seen', '--format', 'gif'],
     "argument --format: invalid choice: 'gif'"),
    ('growspace-camera', ['export', '{bag}', 'seen', '--scale', '3'],
     'argument --scale: 3 is not allowed; expected a number in [0.05, 1]'),
    ('growspace-camera', ['export', '{bag}', '{file}'], "argument out: '{file}' is a file"),
    ('growspace-sweep', ['--workers', '0'], 'argument --workers: 0 is not allowed'),
    ('growspace-sweep', ['--episodes', '1'], 'argument --episodes: 1 is not allowed'),
    ('growspace-sweep', ['--eval-seed', '-1'], 'argument --eval-seed: -1 is not allowed'),
    ('growspace-sweep', ['--steps', '0'], 'argument --steps: 0 is not allowed'),
    ('growspace-sweep', ['--cpus-per-trial', '0'], 'argument --cpus-per-trial: 0 is not'),
    ('growspace-sweep', ['--gpus-per-trial', '-1'], 'argument --gpus-per-trial: -1 is not'),
    ('growspace-sweep', ['nosuch.yaml'], "argument spec: 'nosuch.yaml'"),
    ('growspace-sweep', ['--out', '{file}'], "argument --out: '{file}' is a file"),
    ('growspace-sweep', ['--agents', 'oracle', '--envs', 'GrowSpace/Control-Easy-v0',
                         '--seeds', 'x'], '--seeds takes a count or a comma-separated list'),
    ('growspace-compare', ['--run', '{dir}', '--episodes', '1'],
     'argument --episodes: 1 is not allowed'),
    ('growspace-compare', ['--run', '{dir}', '--workers', '0'], 'argument --workers: 0 is not'),
    ('growspace-compare', ['--run', '{dir}', '--seed', '-1'], 'argument --seed: -1 is not'),
    ('growspace-compare', ['--run', '{dir}', '--out', '{file}'], "argument --out: '{file}' is"),
    ('growspace-compare', ['--run', '{dir}'], 'is not a run directory (no run.json)'),
    ('growspace-train', ['--steps', '0'], 'argument --steps: 0 is not allowed'),
    ('growspace-train', ['--seed', '-1'], 'argument --seed: -1 is not allowed'),
    ('growspace-train', ['--n-envs', '0'], 'argument --n-envs: 0 is not allowed'),
    ('growspace-train', ['--threads', '0'], 'argument --threads: 0 is not allowed'),
    ('growspace-train', ['--checkpoint-every', '0'], 'argument --checkpoint-every: 0 is not'),
    ('growspace-train', ['--log-interval', '0'], 'argument --log-interval: 0 is not'),
    ('growspace-train', ['--max-minutes', '0'], 'argument --max-minutes: 0 is not allowed'),
    ('growspace-train', ['--env-kwargs', '[1]'], "argument --env-kwargs: '[1]' is not allowed"),
    ('growspace-train', ['--env-kwargs', '{'], "argument --env-kwargs: '{' is not JSON"),
    ('growspace-train', ['--algo', 'nope'], "argument --algo: invalid choice: 'nope'"),
    ('growspace-train', ['--out', '{file}'], "argument --out: '{file}' is a file"),
    ('growspace-train', ['--env', 'GrowSpace/Nope-v0'], "unknown env id 'GrowSpace/Nope-v0'"),
    ('growspace-rig', ['run', '{dir}/run', '--episodes', '0'], 'argument --episodes: episodes'),
    ('growspace-rig', ['run', '{dir}/run', '--episodes', 'x'], 'argument --episodes: invalid'),
    ('growspace-rig', ['run', '{dir}/run', '--seed', '-1'], 'argument --seed: seed = -1'),
    ('growspace-rig', ['run', '{dir}/run', '--step-period', '-1'],
     'argument --step-period: step_period_s = -1.0'),
    ('growspace-rig', ['run', '{dir}/run', '--policy', 'nope'],
     "argument --policy: invalid choice: 'nope'"),
    ('growspace-rig', ['run', '{dir}/run', '--challenge', 'nosuch'],
     'argument --challenge/--setting: challenge'),
    ('growspace-rig', ['run', '{dir}/run', '--policy', 'replay'],
     'argument --policy-path: policy_path'),
    ('growspace-rig', ['run', '{dir}/run', '--policy', 'replay', '--policy-path', '{file}'],
     "argument --policy-path: '{file}' cannot be used as a replay policy"),
    ('growspace-rig', ['resume', MISSING], f'{MISSING} is not a run directory'),
    ('growspace-rig', ['status', '{dir}'], 'is not a run directory'),
    ('teleop', ['--ros-args', '-r', '__ns:=bad//ns'],
     "invalid ROS arguments: Couldn't parse remap rule: '-r __ns:=bad//ns'; expected FROM:=TO"),
    ('teleop', ['--ros-args', '--params-file', 'nosuch.yaml'],
     "Couldn't parse params file: '--params-file nosuch.yaml'"),
    ('teleop', ['--nope'], 'unrecognized arguments: --nope'),
] + [(node, ros_args, words) for node in ('sim_node', 'view_node', 'camera_node', 'gantry_node')
     for ros_args, words in (
         (['--ros-args', '-r', '__ns:=bad//ns'],
          "Couldn't parse remap rule: '-r __ns:=bad//ns'; expected FROM:=TO"),
         (['--ros-args', '-r', 'nothing'], "Couldn't parse remap rule: '-r nothing'"),
         (['--ros-args', '-p', 'seed'], "parameter override rule: '-p seed'; expected NAME:="),
         (['--ros-args', '--params-file', 'nosuch.yaml'], "'--params-file nosuch.yaml'"),
         (['-p', 'seed:=1'], "unexpected argument(s) '-p seed:=1'"))]

# What only a starting node can check: its parameters' values (one child process each).
BAD_NODE_PARAMETERS = [
    ('sim_node', ['-p', 'seed:=-3'], 'invalid parameter: seed must be in'),
    ('view_node', ['-p', 'view_size:=8'], 'invalid parameter: view_size must be in [16, 4096]'),
    ('camera_node', ['-p', 'width:=-1'], 'invalid parameter: width must be in [16, 8192]'),
    ('gantry_node', ['-p', 'baud:=-1'], 'invalid parameter: baud must be in'),
]
NODES = {'sim_node', 'view_node', 'camera_node', 'gantry_node'}


def console_scripts() -> dict[str, str]:
    """Every console script of the workspace: name -> 'module:function' (from setup.py)."""
    import re

    scripts = {}
    for setup in (ROOT / 'src').glob('*/setup.py'):
        for name, target in re.findall(r"'([\w-]+) = ([\w.]+:\w+)'", setup.read_text()):
            scripts[name] = target
    return scripts


def test_every_console_script_is_walked() -> None:
    walked = {row[0] for row in BAD_ARGUMENTS + BAD_NODE_PARAMETERS}
    assert set(console_scripts()) == walked


@pytest.fixture
def places(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """An empty working folder with a plain file and a folder in it (the placeholders)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'file.txt').write_text('not a bag, not a photo')
    (tmp_path / 'folder').mkdir()
    return {'file': str(tmp_path / 'file.txt'), 'dir': str(tmp_path / 'folder'),
            'bag': str(BAG)}


def _one_line(err: str, words: str) -> None:
    lines = err.strip().splitlines()
    assert 'Traceback' not in err and len(lines) == 1, err
    assert words in lines[0], lines[0]


NEEDS_TORCH = pytest.mark.skipif(importlib.util.find_spec('torch') is None or
                                 importlib.util.find_spec('stable_baselines3') is None,
                                 reason='growspace-train needs the learn extra')


@pytest.mark.parametrize(('script', 'args', 'words'), [
    pytest.param(*row, marks=NEEDS_TORCH if row[0] == 'growspace-train' else (),
                 id=f'{row[0]} {" ".join(row[1])}') for row in BAD_ARGUMENTS])
def test_a_bad_argument_is_one_line_and_exit_2_before_any_work(
        script: str, args: list[str], words: str, places: dict[str, str], capfd) -> None:
    import importlib
    import signal

    if '{bag}' in ' '.join(args) and not BAG.exists():
        pytest.skip('no sample bags')
    module, function = console_scripts()[script].split(':')
    main = getattr(importlib.import_module(module), function)
    before = sorted(Path.cwd().rglob('*'))
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        code = main([a.format(**places) for a in args])
    except SystemExit as e:
        code = e.code
    finally:  # a node's main() takes SIGINT and SIGTERM over; pytest's own come back
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    err = capfd.readouterr().err
    assert code == 2, err
    _one_line(err, words.format(**places))
    assert sorted(Path.cwd().rglob('*')) == before  # nothing written: no work started


@pytest.mark.parametrize(('script', 'args', 'words'), BAD_NODE_PARAMETERS,
                         ids=[row[0] for row in BAD_NODE_PARAMETERS])
def test_a_node_with_a_bad_parameter_value_says_so_in_one_line(
        script: str, args: list[str], words: str, tmp_path: Path) -> None:
    import subprocess

    from conftest import child_env

    package = {'gantry_node': 'growspace_gantry', 'camera_node': 'growspace_camera'}.get(
        script, 'growspace_sim')
    out = subprocess.run([str(ROOT / 'install' / package / 'lib' / package / script),
                          '--ros-args', *args], cwd=tmp_path, capture_output=True, text=True,
                         timeout=120, env=child_env())
    assert out.returncode == 2, out.stderr
    _one_line(out.stderr, words)


RUN_SH_BAD_ARGUMENTS = {  # run.sh subcommand and arguments: what the error line must hold
    ('eval', '--seed', '-4'): 'growspace-eval: error: argument --seed: -4 is not allowed',
    ('bench', '--episodes', '-5'): 'growspace-bench: error: argument --episodes: -5 is not',
    ('sweep', '--workers', '0'): 'growspace-sweep: error: argument --workers: 0 is not allowed',
    ('demo', '--seed', '-1'): 'growspace-demo: error: argument --seed: -1 is not allowed',
}


def test_run_sh_passes_a_bad_argument_on_and_says_so_in_one_line(tmp_path: Path) -> None:
    import subprocess

    from conftest import child_env

    runs = {case: subprocess.Popen([str(ROOT / 'run.sh'), *case], cwd=tmp_path, text=True,
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                   env=child_env()) for case in RUN_SH_BAD_ARGUMENTS}
    for case, proc in runs.items():  # started together: each pays its imports at once
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 2, (case, err)
        # Beside the error, only run.sh's own line saying where bench, sweep and demo run.
        lines = [line for line in err.strip().splitlines()
                 if not line.startswith(('Running inside a loopback-only', 'No private network'))]
        _one_line('\n'.join(lines), RUN_SH_BAD_ARGUMENTS[case])
