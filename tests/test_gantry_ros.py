"""The installed ``gantry_node`` on real rclpy, driving an emulated GRBL 1.1 on a pty.

The bridge's lockstep link drives it like a simulated chamber (no image: the gantry has no
camera yet); SIGTERM during a move leaves the lamp off and the machine stopped.
"""

from __future__ import annotations

import os
import signal
import time

from ament_index_python.packages import get_package_prefix
import pytest

from grbl_emulator import GrblEmulator
from growspace_gym_bridge.link import ChamberLink
from growspace_sim import convert
from growspace_sim.node.interface import COMMAND_QOS
from growspace_sim.node.rclpy_transport import RclpyTransport
from growspace_sim.ros import types
from ros_helpers import NodeProcess
from test_gantry_node import RIG

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


def test_bridge_link_drives_the_gantry_then_sigterm_mid_move(grbl: GrblEmulator) -> None:
    node = start_gantry(grbl)
    transport = RclpyTransport('gantry_test_client', '/gs_test')
    try:
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
        # A long move, then SIGTERM before it ends.
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
