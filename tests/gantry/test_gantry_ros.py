"""The installed ``gantry_node`` on real rclpy, driving an emulated GRBL 1.1 on a pty.

The bridge's lockstep link drives it like a simulated chamber (no image: the gantry runs without
a camera here: tests/gantry/test_rig_ros.py has one); SIGTERM during a move leaves the lamp off
and the machine stopped.
"""

from __future__ import annotations

import os
import signal
import time
from typing import Any

from ament_index_python.packages import get_package_prefix
import pytest
import yaml

from grbl_emulator import GrblEmulator
from growspace_gantry.main import default_calibration
from growspace_gym_bridge.link import ChamberLink
from growspace_sim.node.rclpy_transport import RclpyTransport
from growspace_sim.replay import compare, format_comparison
from growspace_sim.ros import convert
from growspace_sim.ros import types
from growspace_sim.ros.interface import COMMAND_QOS
from ros_helpers import NodeProcess, wait_until_idle
from test_gantry_node import RIG

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

SPEEDUP = 40.0


def gantry_executable() -> str:
    return os.path.join(get_package_prefix('growspace_gantry'), 'lib', 'growspace_gantry',
                        'gantry_node')


@pytest.fixture
def grbl(tmp_path):
    emulator = GrblEmulator(RIG, speedup=SPEEDUP, link_dir=tmp_path).start()
    yield emulator
    emulator.stop()


def start_gantry(grbl: GrblEmulator, *args: str) -> NodeProcess:
    return NodeProcess('-p', f'port:={grbl.port}', '-p', 'seed:=3', *args,
                       executable=gantry_executable())


@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
def test_bridge_link_drives_the_gantry_then_sigterm_mid_move(grbl: GrblEmulator) -> None:
    node = start_gantry(grbl)
    transport = RclpyTransport('gantry_test_client', '/gs_test')
    try:
        wait_until_idle('/gs_test')  # before that it refuses a reset: the controller boots
        link = ChamberLink(transport, with_state=True, with_image=False)
        config = link.connect(20.0)
        assert config['source'] == 'gantry'
        reply = link.reset(1, seed=5, challenge='control', setting='easy', timeout_s=20.0)
        assert reply.result.info == '' and reply.light is not None
        for step_id, action in enumerate((0, 0, 1, 3, 4, 2), start=1):
            reply = link.step(1, step_id, 20.0, action=action)
            assert (reply.result.step_id, reply.result.info) == (step_id, '')
            assert reply.light.step_id == step_id
            assert grbl.state == 'Idle'
        assert grbl.spindle == ('M3', 1000.0)
        # A long move, then SIGTERM before it ends: ten times slower than the steps (5-8 s),
        # so that a loaded machine's delay in stopping cannot let it end first.
        grbl.speedup = SPEEDUP / 10.0  # (the machine stands Idle: no block in motion)
        publish = transport.publisher(types.LIGHT_COMMAND, 'light/command', COMMAND_QOS)
        publish(types.new(types.LIGHT_COMMAND, step_id=7, mode=convert.MODE_BEAM, x=0.8,
                          width=0.2))  # not awaited
        deadline = time.monotonic() + 10.0
        while grbl.state != 'Jog' and time.monotonic() < deadline:
            time.sleep(0.005)
        assert grbl.state == 'Jog'
        code, log = node.stop(signal.SIGTERM)
        assert code == 0, log
        assert grbl.spindle[0] == 'M5', log
        assert grbl.state in ('Idle', 'Alarm')
        assert grbl.mpos[0] < -845.0 + 800.0 - 1.0  # stopped short of the target
        assert '$X' not in grbl.lines
    finally:
        transport.close()
        node.stop(signal.SIGKILL)


def test_invalid_calibration_exits_2_naming_the_key(grbl: GrblEmulator, tmp_path) -> None:
    bad = tmp_path / 'gantry.yaml'
    bad.write_text('x: {axis: Q}\n')
    node = start_gantry(grbl, '-p', f'calibration:={bad}')
    code, log = node.stop(signal.SIGCONT)  # let it end by itself
    assert code == 2
    assert "x.axis = 'Q' must be X, Y or Z" in log
    assert grbl.lines == []  # nothing was sent


BAG = os.path.join(os.path.dirname(__file__), '..', '..', 'bags', 'oracle_control_hard.mcap')


def replay_onto_gantry(tmp_path, *params: str, **play: Any) -> Any:
    """Start gantry_node (seed 5: not the bag's) on an emulated GRBL, wait until it stands
    Idle, replay the sample episode step by step onto it; returns the replay's report."""
    from growspace_sim.replay.play import play_steps

    with GrblEmulator(RIG, speedup=400.0, link_dir=tmp_path) as grbl:
        node = NodeProcess('-p', f'port:={grbl.port}', '-p', 'seed:=5', '-p', 'status_hz:=50.0',
                           '-p', f'record_path:={tmp_path / "hardware.mcap"}', *params,
                           namespace='/growspace', executable=gantry_executable())
        try:
            wait_until_idle('/growspace')
            return play_steps(BAG, wait_for_subscribers_s=20.0, step_timeout_s=60.0, **play)
        finally:
            node.stop()


def test_a_recorded_agent_episode_replayed_onto_the_gantry(tmp_path) -> None:
    """``growspace-replay play --step-period`` drives the gantry through a sample oracle
    episode: its reset first (the gantry started with another seed), then each step once the
    previous one is answered. The reached light matches the simulator's within the tolerance,
    step_id by step_id, from the two recordings as a user compares them."""
    report = replay_onto_gantry(tmp_path, step_period_s=0.0)
    assert (report.requests, report.answered, report.failures, report.stopped) == (51, 51, [],
                                                                                  '')
    result = compare(BAG, tmp_path / 'hardware.mcap')
    print(format_comparison(result))
    assert result.steps == 51 and not result.skipped and not result.unmatched, \
        format_comparison(result)
    assert result.errors['x'].max_abs <= 0.05e-3 + 1e-9  # position_tolerance_mm
    assert result.errors['width'].max_abs <= 2 * 0.05e-3 + 1e-9  # 2 x lamp height


def test_a_step_the_gantry_refuses_stops_the_replay_with_its_reason(tmp_path) -> None:
    data = yaml.safe_load(open(default_calibration(), encoding='utf-8'))
    data['x']['min_mm'] = -600.0  # step_id 10 of the sample episode lies beyond it
    cal = tmp_path / 'narrow.yaml'
    cal.write_text(yaml.safe_dump(data))
    report = replay_onto_gantry(tmp_path, '-p', f'calibration:={cal}', step_period_s=0.0)
    assert (report.requests, report.answered) == (11, 10)
    assert report.stopped.startswith('episode 0, step 10/50 (step_id 10) failed on the node')
    assert 'outside its travel [-600.0, -5.0]' in report.stopped
    result = compare(BAG, tmp_path / 'hardware.mcap')
    assert result.steps == 10 and result.unmatched == ['episode 0, step_id 10-50: only in A']
