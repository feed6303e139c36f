"""The README and docs/, followed as written (issue 26): every command a page shows is either run
here, in the README's own shell set-up, or listed below with the reason it cannot run on a CI
machine (a serial device, torch, a second machine, ros2cli) and where it is tried instead.

A command added to a page without a row in ``WHERE`` fails
``test_every_documented_command_is_run_here_or_says_why_not``: nothing is skipped in silence.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import shlex
import shutil
import subprocess

import pytest

from conftest import child_env
from waiting import wait_until

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md'))]
SAMPLE = 'bags/oracle_control_easy.mcap'
RUN = 'run here (this file)'
# (pattern on the command, how it is checked). Order matters: the first match wins.
WHERE = [
    (r'^\./run\.sh demo$', 'covered: tests/tools/test_demo.py runs the demo, recordings checked'),
    (r'^\./run\.sh test$', 'CI: .ci/run runs it; it is this suite'),
    (r'^\./run\.sh test ', "pytest's arguments, passed through: tests/tools/test_run_sh.py runs a "
                           'file, collects the suite and the quick tier through run.sh'),
    (r'^eval "\$\(\./run\.sh env\)"$', RUN),
    (r'^colcon build --symlink-install$', RUN),
    (r'^ros2 ', 'needs ros2cli / ros2 launch, not on PyPI (observed by hand: README, ROS 2)'),
    (r'^teleop ', 'needs a terminal: tests/tools/test_teleop.py drives it through a pty'),
    (r'^gantry_node ', 'needs a serial device: tests/gantry/test_gantry_docs.py runs it as '
                       'written against the GRBL emulator'),
    (r'^growspace-gantry-gcode ', 'covered: tests/gantry/test_gantry_docs.py runs it as written'),
    (r'^growspace-replay play BAG --step-period ',
     'needs the gantry: tests/gantry/test_gantry_docs.py parses it, '
     'tests/recording/test_replay_steps.py plays'),
    (r'^growspace-replay play run\.mcap --step-period ',
     'needs a lockstep node: tests/recording/test_replay_steps.py plays it'),
    (r'^(sim_node|view_node) --ros-args', RUN),
    (r'^camera_node .*source:=/dev/video', 'needs a camera (V4L2): tests read photos and videos '
                                          'instead (tests/camera/)'),
    (r'^camera_node --ros-args', RUN),
    (r'^growspace-camera (resegment|export) ',
     'needs a rig recording (gantry_node with a camera): tests/camera/test_camera_resegment.py '
     'makes one and runs these lines as written'),
    (r'^growspace-camera ', RUN),
    (r'^python -m growspace_sim\.tools\.pub ', RUN),
    (r'^growspace-replay ', RUN),
    (r'^growspace-rig run .*--chamber attach ', 'needs a running lockstep chamber (the rig): '
                                               'tests/rig/test_rig_run.py runs sim_node instead'),
    (r'^growspace-rig (run|resume|status) runs/exp1', 'covered: tests/rig/test_rig_run.py runs '
                                                     '`run`, SIGKILL, `resume` on sim_node; '
                                                     'tests/rig/test_rig_rundir.py `status`'),
    (r'^(growspace-sweep .*--address HEAD_IP|export RAY_AUTH_MODE|ray |mkdir -p ~/\.ray |'
     r'RAY_ARGS=|\(umask 077 && ray get-auth-token|ssh OTHER )',
     'the cluster recipe needs machines (walked by hand on two namespaced nodes: README); '
     'one loopback node with a token: tests/sim/test_sweep.py'),
    (r'^growspace-sweep config/sweeps/case_studies\.yaml$', 'needs torch (the learn extra) and '
                                                          'hours of training'),
    (r'^growspace-sweep ', 'covered: tests/sim/test_sweep.py runs evaluation sweeps'),
    (r'^(pip install -r requirements-learn\.txt|growspace-train |growspace-compare --run )',
     'needs torch (the learn extra): tests/sim/test_learn.py where it is installed'),
    (r'^python scripts/case_studies\.py ', 'a record of past runs: the script is in git '
                                           'history (920d50b), docs/baselines.md says so'),
    (r'^python scripts/learning_budget\.py ', 'needs torch and hours on a GPU machine: '
     'tests/sim/test_learn.py tests its resume and device buffer; docs/baselines.md records its '
     'run'),
]


def bash_lines(path: Path) -> list[str]:
    """The command lines of a page's ```bash blocks (continuations joined, comments dropped)."""
    out, block, joined = [], False, ''
    for line in path.read_text(encoding='utf-8').splitlines():
        if line.startswith('```'):
            block = line.strip() == '```bash' if not block else False
            continue
        if not block or line.lstrip().startswith('#'):
            continue
        joined += re.split(r'\s#\s', line)[0].rstrip()
        if joined.endswith('\\'):
            joined = joined[:-1] + ' '
            continue
        if joined.strip():
            out.append(' '.join(joined.split()))
        joined = ''
    return out


def documented() -> list[tuple[str, str]]:
    return [(page.name, line) for page in PAGES for line in bash_lines(page)]


def how(line: str) -> str:
    return next((why for pattern, why in WHERE if re.search(pattern, line)), '')


def shell(script: str, cwd: Path = ROOT, timeout: float = 300) -> subprocess.CompletedProcess:
    """``script`` in bash after the README's set-up line, as a user's shell runs it."""
    return subprocess.run(['bash', '-c', f'eval "$(./run.sh env)" && cd {shlex.quote(str(cwd))} '
                                         f'&& {script}'],
                          cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                          env=child_env())


def test_every_documented_command_is_run_here_or_says_why_not() -> None:
    lines = documented()
    assert len(lines) > 20
    unplaced = [f'{page}: {line}' for page, line in lines if not how(line)]
    assert not unplaced, 'add a row to WHERE for:\n' + '\n'.join(unplaced)
    print('\n'.join(f'{page}: {line}\n    -> {how(line)}' for page, line in lines))


@pytest.mark.slow
def test_the_shell_set_up_runs_the_tools_and_colcon_builds(tmp_path) -> None:
    base = tmp_path / 'ws'
    # The README's `colcon build --symlink-install`, into a scratch build and install base (the
    # workspace's own are in use), for the package whose build needs the venv's underlay.
    out = shell(f'growspace-replay info {SAMPLE} && colcon --log-base {base}/log build '
                f'--symlink-install --base-paths src --packages-select growspace_msgs '
                f'--build-base {base}/build --install-base {base}/install', timeout=600)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert '1 episode(s), 50 step(s)' in out.stdout \
        and (base / 'install' / 'growspace_msgs').is_dir()


def _placed(line: str, work: Path) -> str:
    """A documented line with its placeholders filled from the sample bag, in ``work``."""
    line = re.sub(r'\[([^\]|]+)(\|[^\]]*)?\]', lambda m: m.group(1).strip(), line)  # first choice
    for name in ('run.mcap', 'sim.mcap', 'gantry.mcap', 'BAG', 'HW.mcap'):
        line = line.replace(name, str(work / 'run.mcap'))
    line = line.replace('bags/oracle_control_easy.mcap', str(ROOT / SAMPLE))
    return line.replace('broken.mcap', str(work / 'broken.mcap'))


@pytest.mark.slow
def test_the_recording_tools_run_as_written(tmp_path) -> None:
    shutil.copy(ROOT / SAMPLE, tmp_path / 'run.mcap')
    data = (ROOT / SAMPLE).read_bytes()
    (tmp_path / 'broken.mcap').write_bytes(data[:len(data) * 2 // 3])  # a run cut short
    lines = [line for _, line in documented()
             if line.startswith('growspace-replay ') and how(line) == RUN]
    assert any(' recover ' in line for line in lines) and any(' play ' in line for line in lines)
    for line in lines:
        placed = _placed(line, tmp_path)
        if ' play ' in placed:
            placed += ' --wait 0'  # nobody listens here; the republishing itself is the check
        out = shell(placed, cwd=tmp_path)
        assert out.returncode == 0, (line, out.stdout[-2000:], out.stderr[-2000:])


@pytest.mark.slow
def test_the_launch_files_nodes_by_hand_meet_and_answer_the_pub_lines(tmp_path) -> None:
    nodes = [line for _, line in documented() if re.match(r'^(sim_node|view_node) --ros-args',
                                                          line) and how(line) == RUN]
    pubs = [line for _, line in documented() if line.startswith('python -m growspace_sim.tools')]
    assert len(nodes) >= 3 and len(pubs) == 2
    script = '\n'.join(line.replace('foxglove_port:=8765', 'foxglove_port:=0')
                        if line.endswith('&') else line + ' &' for line in nodes)
    started = subprocess.Popen(['bash', '-c', f'eval "$(./run.sh env)"\n{script}\nwait'],
                               cwd=ROOT, env=child_env(), start_new_session=True,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        # Until both chambers and the view are on the graph (started: no signal lands in their
        # imports), then the pub lines, which wait for their readers themselves.
        probe = ('from growspace_sim.node.rclpy_transport import RclpyTransport\n'
                 'import time\n'
                 't = RclpyTransport("readme_probe")\n'
                 'view = ("growspace_view", "/chamber1")\n'
                 'end = time.monotonic() + 90\n'
                 'while (len(t.chamber_namespaces()) < 2 or view not in\n'
                 '       t.node.get_node_names_and_namespaces()) and time.monotonic() < end:\n'
                 '    t.spin_once(0.1)\n'
                 'print(t.chamber_namespaces(), view in t.node.get_node_names_and_namespaces())\n'
                 't.close()\n')
        (tmp_path / 'probe.py').write_text(probe)
        seen = shell(f'python {tmp_path / "probe.py"}', timeout=120)
        assert "['/chamber1', '/growspace'] True" in seen.stdout, seen.stdout + seen.stderr
        for line in pubs:  # the first step of the node's first episode, then a reset
            out = shell(line, timeout=120)
            assert out.returncode == 0 and 'published on /growspace/' in out.stdout, out.stderr
            assert 'no subscriber' not in out.stderr, out.stderr
    finally:
        os.killpg(started.pid, 2)
        log = started.communicate(timeout=60)[0]
    assert 'Traceback' not in log and 'invalid' not in log, log[-3000:]
    assert 'light/command:' not in log and 'reset: rejected' not in log, log[-3000:]  # accepted


@pytest.mark.parametrize('page', PAGES, ids=lambda p: p.name)
def test_no_page_names_a_script_or_file_that_is_not_here(page: Path) -> None:
    missing = []
    for line in bash_lines(page):
        for word in shlex.split(line, posix=True):
            if re.fullmatch(r'(scripts|config|src|bags)/[\w./-]+', word) \
                    and not (ROOT / word).exists() and how(line) == RUN:
                missing.append(f'{line}: {word}')
    assert not missing, missing


@pytest.mark.slow
def test_the_camera_lines_run_as_written(tmp_path) -> None:
    # In page order: the sheet, twin photos into shots/, measuring them, then camera_node on the
    # twin and on those photos (started until its source is open, then stopped by SIGINT).
    lines = [line for _, line in documented() if how(line) == RUN and (
        line.startswith('growspace-camera ') or line.startswith('camera_node '))]
    tools = [line for line in lines if line.startswith('growspace-camera ')]
    nodes = [line for line in lines if line.startswith('camera_node ')]
    assert len(tools) >= 3 and len(nodes) >= 2
    for line in sorted(tools, key=lambda x: (' measure ' in x, x)):  # photos before measuring
        out = shell(line, cwd=tmp_path)
        assert out.returncode == 0, (line, out.stdout[-2000:], out.stderr[-2000:])
    assert (tmp_path / 'sheet.svg').is_file() and list((tmp_path / 'shots').glob('*.jpg'))
    for i, line in enumerate(nodes):
        path = tmp_path / f'camera_node_{i}.log'
        with open(path, 'w') as out:
            node = subprocess.Popen(['bash', '-c', f'eval "$(./run.sh env)" && cd {tmp_path} && '
                                                   f'exec {line}'],
                                    cwd=ROOT, env=child_env(), stdout=out,
                                    stderr=subprocess.STDOUT, text=True)
        try:
            wait_until(lambda p=path, n=node: re.search(r'camera: .* open: ', p.read_text())
                       or n.poll() is not None, 120.0, f'{line}: its source opens',
                       detail=lambda p=path: p.read_text()[-3000:])
            alive = node.poll() is None
            node.send_signal(2)
            node.wait(timeout=60)
        finally:
            if node.poll() is None:
                node.kill()
                node.wait()
        log = path.read_text()
        assert alive and node.returncode == 0 and 'Traceback' not in log, (line, log[-3000:])
