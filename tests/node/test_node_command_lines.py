"""Every node's command line: no argument ignored in silence, one namespace where they meet.

Issue 26: ``gantry_node -p record_path:=HW.mcap`` (no ``--ros-args``) recorded nothing and said
nothing; a view beside a chamber in another namespace waited in silence.
"""

from __future__ import annotations

from pathlib import Path
import signal
import subprocess
import time

import pytest

from conftest import child_env
from ros_helpers import Client, NodeProcess
from waiting import wait_until

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
NODES = ('sim_node', 'gantry_node', 'view_node')


def executable(name: str) -> str:
    package = 'growspace_gantry' if name == 'gantry_node' else 'growspace_sim'
    return str(ROOT / 'install' / package / 'lib' / package / name)


@pytest.mark.parametrize('name', NODES)
def test_an_argument_without_ros_args_is_refused_with_the_fix(name: str, tmp_path) -> None:
    record = tmp_path / 'run.mcap'
    out = subprocess.run([executable(name), '-p', f'record_path:={record}'], cwd=tmp_path,
                         capture_output=True, text=True, timeout=60, env=child_env())
    assert out.returncode == 2, out.stderr
    assert f'did you mean `{name} --ros-args -p record_path:={record}`?' in out.stderr
    assert 'Traceback' not in out.stderr and not record.exists()


@pytest.mark.parametrize('name', NODES)
def test_help_says_how_to_pass_ros_arguments(name: str) -> None:
    out = subprocess.run([executable(name), '--help'], capture_output=True, text=True,
                         timeout=60, env=child_env())
    assert out.returncode == 0, out.stderr
    assert f'usage: {name} [--ros-args' in out.stdout and '/growspace' in out.stdout


def test_a_view_beside_no_chamber_says_where_the_chambers_are() -> None:
    chamber = NodeProcess('-p', 'seed:=1', namespace=None)  # the default namespace
    said = 'view_node: no chamber in /elsewhere after 5 s; chambers are in /growspace'
    view = None
    try:
        client = Client('/growspace')  # the chamber on the graph first: the view looks once
        try:
            client.connect()
        finally:
            client.close()
        view = NodeProcess(namespace='/elsewhere', executable=executable('view_node'))
        # presence.AFTER_S (5 s) after the view started, which a loaded machine delays.
        wait_until(lambda: said in view.output() or view.proc.poll() is not None, 90.0,
                   'the view says where the chambers are',
                   detail=lambda: view.output()[-2000:])
    finally:
        code, out = view.stop(signal.SIGINT) if view is not None else (None, '')
        chamber.stop()
    assert said in out and code == 0, out[-2000:]


def test_the_gantry_takes_the_simulators_params_file_without_crying_typo(tmp_path) -> None:
    from grbl_emulator import GrblEmulator
    from test_gantry_node import RIG

    with GrblEmulator(RIG, speedup=40.0, link_dir=tmp_path) as grbl:
        proc = subprocess.Popen(
            [executable('gantry_node'), '--ros-args', '--params-file',
             str(ROOT / 'config' / 'growspace.yaml'), '-p', f'port:={grbl.port}'],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=child_env())
        try:
            deadline = time.monotonic() + 90.0  # its start-up on a loaded machine
            while '$$' not in grbl.lines and time.monotonic() < deadline \
                    and proc.poll() is None:
                time.sleep(0.05)
            assert '$$' in grbl.lines, proc.poll()  # up, its parameters read
        finally:
            proc.send_signal(signal.SIGINT)
            out = proc.communicate(timeout=20)[0]
    assert proc.returncode == 0, out
    # record_max_* and resume_path are the gantry's own too (its split recording and resume)
    assert "sim_node parameter(s) ['auto_reset', 'image_frame_id', 'rate_hz'] do not apply" \
        in out
    assert 'typo' not in out

