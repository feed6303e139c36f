"""The installed ``gantry_node`` on real rclpy, driving an emulated GRBL 1.1 on a pty.

The bridge's lockstep link drives it like a simulated chamber (no image: the gantry has no
camera yet); SIGTERM during a move leaves the lamp off and the machine stopped.
"""

from __future__ import annotations

import os
import signal
import threading
import time

from ament_index_python.packages import get_package_prefix
import numpy as np
import pytest

from grbl_emulator import GrblEmulator
from growspace_gym_bridge.link import ChamberLink
from growspace_sim.node.rclpy_transport import RclpyTransport
from growspace_sim.replay import compare, format_comparison
from growspace_sim.ros import convert
from growspace_sim.ros import types
from growspace_sim.ros.interface import COMMAND_QOS
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


def test_a_recorded_agent_episode_replayed_onto_the_gantry(tmp_path) -> None:
    """``growspace-replay play --only light/command --step-period`` drives the gantry through
    a sample oracle episode; the reached light matches the simulator's within the tolerance."""
    from growspace_sim.replay.play import play
    from growspace_sim.replay.bag import Bag

    bag = os.path.join(os.path.dirname(__file__), '..', 'bags', 'oracle_control_hard.mcap')
    with Bag(bag) as b:
        sim_lights = {m.step_id: m for m in (x.decode() for x in
                                             b.messages(['/growspace/light/state']))}
    # Each step must be answered within the period (a status report at Idle on target), also
    # on a loaded CI machine: fast moves, 50 Hz status, 0.3 s per step.
    with GrblEmulator(RIG, speedup=400.0, link_dir=tmp_path) as grbl:
        node = NodeProcess('-p', f'port:={grbl.port}', '-p', 'seed:=2024', '-p',
                           'challenge:=control', '-p', 'setting:=hard', '-p', 'status_hz:=50.0',
                           '-p', f'record_path:={tmp_path / "hardware.mcap"}',
                           namespace='/growspace',
                           executable=gantry_executable())
        listener = RclpyTransport('replay_listener', '/growspace')
        reached, results = {}, []
        try:
            listener.subscribe(types.LIGHT_COMMAND, 'light/state', COMMAND_QOS,
                               lambda m, _: reached.__setitem__(m.step_id, m))
            listener.subscribe(types.STEP_RESULT, 'step_result', COMMAND_QOS,
                               lambda m, _: results.append(m))
            ready: list = []  # gantry/status (1 Hz and on change) at level OK: Idle, connected
            listener.subscribe('diagnostic_msgs/msg/DiagnosticArray', 'gantry/status',
                               COMMAND_QOS, lambda m, _: ready.extend(
                                   s for s in m.status if s.level == 0))
            deadline = time.monotonic() + 20.0
            while not (listener.matched('step_result') and ready) \
                    and time.monotonic() < deadline:
                listener.spin_once(0.05)
            assert ready, 'the gantry never reported itself ready'
            played: list = []

            def replay() -> None:
                try:
                    played.append(play(bag, topics=['/growspace/light/command'],
                                            step_period_s=0.3, wait_for_subscribers_s=10.0))
                except Exception as e:  # noqa: BLE001 - shown by the assertion below
                    played.append(e)
            thread = threading.Thread(target=replay)
            thread.start()
            deadline = time.monotonic() + 40.0
            while (thread.is_alive() or len(results) < 50) and time.monotonic() < deadline:
                listener.spin_once(0.05)
        finally:
            listener.close()
            node.stop()
    assert played == [50]
    assert [r.info for r in results] == [''] * 50, [r.info for r in results if r.info]
    errors = np.array([[abs(reached[i].x - sim_lights[i].x), abs(reached[i].width -
                                                                 sim_lights[i].width)]
                       for i in range(1, 51)]) * 1000.0  # mm
    # The same figures from the two recordings, as a user gets them after a hardware replay.
    result = compare(bag, tmp_path / 'hardware.mcap')
    print(format_comparison(result))
    assert result.steps >= 50 and not result.skipped, format_comparison(result)
    assert result.errors['x'].max_abs * 1000.0 == pytest.approx(errors[:, 0].max(), abs=1e-9)
    assert errors[:, 0].max() <= 0.05 + 1e-6  # position_tolerance_mm of the calibration
    assert errors[:, 1].max() <= 2 * 0.05 + 1e-6  # width = 2 x lamp height above the canopy
    assert result.within(2 * 0.05e-3 + 1e-9)
