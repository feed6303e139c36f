"""gantry_node's logic against an emulated GRBL 1.1 on a pseudo-terminal (no hardware, no ROS).

The node runs over the in-process transport; time is real (the emulator moves in real time,
``SPEEDUP`` times faster). Every scenario asserts what reached the port, byte for byte where
safety is concerned: a refused command is never written, the lamp ends off after every fault.
"""

from __future__ import annotations

import json
import math
import time
from typing import Any

import numpy as np
import pytest
import yaml

from grbl_emulator import GrblEmulator
from growspace_gantry import calibration
from growspace_gantry.controller import GrblController, Log
from growspace_gantry.link import SerialLink
from growspace_gantry.main import default_calibration
from growspace_gantry.node import GantryNode
from growspace_gantry.settings import GantryParams
from growspace_sim.core.config import SimConfig
from growspace_sim.node.fake import FakeTransport
from growspace_sim.ros import convert
from growspace_sim.ros import types
from growspace_sim.simulation import Simulation

SPEEDUP = 40.0
# A homed rig with laser mode and soft limits, as docs/hardware.md sets it up.
RIG = {10: 1, 20: 1, 22: 0, 30: 1000, 32: 1, 110: 6000, 111: 6000, 112: 6000, 130: 900,
       131: 900, 132: 500}


def load_cal(**changes: Any) -> calibration.Calibration:
    with open(default_calibration(), encoding='utf-8') as f:
        data = yaml.safe_load(f)
    data.update(changes)
    return calibration.from_dict(data)


class Rig:
    """An emulated controller, a gantry node on a fake transport, and helpers to drive them."""

    def __init__(self, tmp_path, settings=None, cal=None, emulator: dict | None = None,
                 clock=time.monotonic, wall_clock=time.time, resume=None, recorder=None,
                 **params: Any) -> None:
        self.grbl = GrblEmulator({**RIG, **(settings or {})}, link_dir=tmp_path,
                                 **{'speedup': SPEEDUP, **(emulator or {})}).start()
        self.transport = FakeTransport('growspace_gantry')
        self.cal = cal or load_cal()
        t = self.transport
        self.controller = GrblController(lambda: SerialLink(self.grbl.port), self.cal,
                                         Log(t.logger.warn, t.logger.info), 0.02,
                                         photo_light=params.get('photo_light', False))
        self.node = GantryNode(t, self.controller, SimConfig(), GantryParams(
            port=self.grbl.port, **{'seed': 7, **params}), recorder=recorder,
            clock=clock, wall_clock=wall_clock, resume=resume)

    def run_until(self, condition, timeout: float = 5.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.node.poll()
            if condition():
                return True
            time.sleep(0.002)
        return False

    def ready(self) -> None:
        assert self.run_until(lambda: self.controller.ready), self.transport.warnings

    def results(self) -> list[Any]:
        return self.transport.messages('step_result')

    def command(self, step_id: int, **fields: Any) -> Any:
        """Send a LightCommand and wait for its StepResult (lockstep)."""
        before = len(self.results())
        self.transport.inject('light/command', types.new(types.LIGHT_COMMAND, step_id=step_id,
                                                         **fields))
        assert self.run_until(lambda: len(self.results()) > before), self.transport.warnings
        assert len(self.results()) == before + 1  # exactly one answer
        return self.results()[-1]

    def close(self) -> None:
        self.node.close()
        self.grbl.stop()


@pytest.fixture
def rig(tmp_path):
    r = Rig(tmp_path)
    yield r
    r.close()


def jogs(grbl: GrblEmulator) -> list[str]:
    return [line for line in grbl.lines if line.startswith('$J=')]


def test_connects_reads_settings_and_starts_with_the_lamp_off(rig: Rig) -> None:
    rig.ready()
    assert rig.grbl.realtime[0] == 0x18  # a soft reset first: a known state
    assert rig.grbl.lines[0] == '$$'  # nothing before the banner, then the settings
    assert rig.run_until(lambda: 'M5' in rig.grbl.lines)
    assert jogs(rig.grbl) == []  # the machine does not move at start-up
    assert rig.transport.messages('chamber/config')


@pytest.mark.slow
def test_lockstep_episode_follows_the_simulator_light(rig: Rig) -> None:
    """Discrete actions mean the same light as in the simulator; each step is answered once,
    when the machine is Idle at the target, with the reached light."""
    rig.ready()
    reset = types.new(types.RESET_REQUEST, reset_id=1, has_seed=True, seed=11,
                      challenge='control', setting='hard')
    rig.transport.inject('reset', reset)
    assert rig.run_until(lambda: rig.results() and rig.results()[-1].reset_id == 1)
    sim = Simulation(SimConfig(challenge='control', setting='hard'))
    sim.reset(seed=11)
    # The episode's target is recorded with its config, as the camera would be sent it.
    config = json.loads(rig.transport.messages('chamber/config')[-1].data)
    assert (config['reset_id'], config['source']) == (1, 'gantry')
    assert config['target'] == {'x': sim.chamber.target.real, 'z': sim.chamber.target.imag}
    rng = np.random.default_rng(0)
    for step_id in range(1, 13):
        action = int(rng.integers(5))
        sim.apply_discrete(action)
        result = rig.command(step_id, mode=convert.MODE_DISCRETE, action=action)
        assert (result.step_id, result.reset_id, result.step, result.info) == (
            step_id, 1, step_id, '')
        reached = rig.transport.messages('light/state')[-1]
        assert reached.step_id == step_id and reached.header.stamp == result.header.stamp
        tol = rig.cal.position_tolerance_mm / 1000
        assert reached.x == pytest.approx(sim.chamber.light.x, abs=tol)
        assert reached.width == pytest.approx(sim.chamber.light.width, abs=2 * tol)
        assert rig.grbl.state == 'Idle'
    assert rig.grbl.spindle == ('M3', 1000.0)  # lamp on at lamp_power 1.0
    assert not rig.grbl.overflowed and rig.grbl.max_rx_used <= 128
    assert all(err not in rig.grbl.lines for err in ('$X', '$H'))


def test_nan_and_out_of_travel_commands_are_never_written(tmp_path) -> None:
    rig = Rig(tmp_path, cal=load_cal(x={'axis': 'X', 'mm_per_m': 1000.0, 'offset_mm': -845.0,
                                        'direction': 1, 'min_mm': -600.0, 'max_mm': -5.0}))
    try:
        rig.ready()
        ok = rig.command(1, mode=convert.MODE_BEAM, x=0.5, width=0.2)
        assert ok.info == ''
        written = rig.grbl.received
        bad = rig.command(2, mode=convert.MODE_BEAM, x=math.nan, width=0.2)
        assert 'x' in bad.info and 'nan' in bad.info
        far = rig.command(3, mode=convert.MODE_BEAM, x=0.1, width=0.2)
        assert 'outside its travel [-600.0, -5.0]' in far.info
        unknown = rig.command(4, mode=9)
        assert 'mode' in unknown.info
        time.sleep(0.05)
        rig.node.poll()
        # Only status requests went out meanwhile: no line at all.
        assert set(rig.grbl.received[len(written):]) <= {ord('?')}
        assert rig.command(5, mode=convert.MODE_BEAM, x=0.45, width=0.2).info == ''
    finally:
        rig.close()


@pytest.mark.slow
def test_a_newer_command_cancels_the_running_jog(rig: Rig) -> None:
    rig.ready()
    rig.node.params = GantryParams(port=rig.grbl.port, mode='realtime')
    far = types.new(types.LIGHT_COMMAND, mode=convert.MODE_BEAM, x=0.7, width=0.2)
    near = types.new(types.LIGHT_COMMAND, mode=convert.MODE_BEAM, x=0.2, width=0.2)
    rig.transport.inject('light/command', far)
    assert rig.run_until(lambda: rig.grbl.state == 'Jog')
    rig.transport.inject('light/command', near)
    assert rig.run_until(lambda: rig.controller.reached())
    assert 0x85 in rig.grbl.realtime  # jog cancel, never a queue of stale moves
    assert rig.grbl.mpos[0] == pytest.approx(-845.0 + 200.0, abs=0.05)


@pytest.mark.slow
def test_watchdog_turns_the_lamp_off_and_holds(tmp_path) -> None:
    rig = Rig(tmp_path, watchdog_s=0.3)
    try:
        rig.ready()
        assert rig.command(1, mode=convert.MODE_BEAM, x=0.3, width=0.2).info == ''
        assert rig.grbl.spindle[0] == 'M3'
        assert rig.run_until(lambda: rig.grbl.spindle[0] == 'M5', timeout=3.0)
        assert any('watchdog' in w for w in rig.transport.warnings)
        assert rig.command(2, mode=convert.MODE_BEAM, x=0.35, width=0.2).info == ''
        assert rig.grbl.spindle[0] == 'M3'  # the next command lights it again
    finally:
        rig.close()


def held_then_reset(grbl: GrblEmulator) -> bool:
    """A feed hold followed by a soft reset reached the controller (status polls between)."""
    return bytes([0x21, 0x18]) in bytes(b for b in grbl.realtime if b != 0x3F)


@pytest.mark.slow
def test_estop_mid_move_stops_and_turns_the_lamp_off(rig: Rig) -> None:
    rig.ready()
    assert rig.command(1, mode=convert.MODE_BEAM, x=0.2, width=0.2).info == ''
    assert rig.grbl.spindle[0] == 'M3'
    rig.transport.inject('light/command', types.new(
        types.LIGHT_COMMAND, step_id=2, mode=convert.MODE_BEAM, x=0.75, width=0.2))
    assert rig.run_until(lambda: rig.grbl.state == 'Jog')
    response = rig.transport.services['gantry/estop'](types.new('std_srvs/srv/Trigger_Request'))
    assert response.success
    assert rig.run_until(lambda: held_then_reset(rig.grbl))
    assert rig.results()[-1].step_id == 2 and 'emergency stop' in rig.results()[-1].info
    assert rig.run_until(lambda: rig.controller.phase == 'ready')
    assert rig.grbl.spindle[0] == 'M5' and rig.grbl.state in ('Idle', 'Alarm')
    stopped_at = rig.grbl.mpos
    assert stopped_at[0] < -845.0 + 750.0 - 1.0  # it did not go on to the target
    time.sleep(0.1)
    rig.node.poll()
    assert rig.grbl.mpos == stopped_at and rig.grbl.spindle[0] == 'M5'
    # The topic form does the same.
    rig.grbl.realtime.clear()
    rig.transport.inject('gantry/estop', types.new('std_msgs/msg/Empty'))
    assert rig.run_until(lambda: held_then_reset(rig.grbl))


@pytest.mark.slow
def test_alarm_mid_episode_fails_the_step_and_only_a_person_unlocks(rig: Rig) -> None:
    rig.ready()
    rig.transport.inject('light/command', types.new(
        types.LIGHT_COMMAND, step_id=1, mode=convert.MODE_BEAM, x=0.8, width=0.2))
    assert rig.run_until(lambda: rig.grbl.state == 'Jog')
    rig.grbl.trigger_alarm(1)
    assert rig.run_until(lambda: rig.results() and rig.results()[-1].step_id == 1)
    assert 'ALARM:1' in rig.results()[-1].info and 'hard limit' in rig.results()[-1].info
    assert 'gantry not ready' in rig.command(2, mode=convert.MODE_BEAM, x=0.5, width=0.2).info
    status = rig.transport.messages('gantry/status')[-1].status[0]
    assert status.level == 2 and 'ALARM:1' in status.message
    time.sleep(0.2)
    rig.node.poll()
    assert '$X' not in rig.grbl.lines  # never unlocked by the driver
    response = rig.transport.services['gantry/unlock'](types.new('std_srvs/srv/Trigger_Request'))
    assert response.success
    assert rig.run_until(lambda: rig.controller.ready)
    assert rig.grbl.lines.count('$X') == 1
    assert rig.command(3, mode=convert.MODE_BEAM, x=0.5, width=0.2).info == ''


@pytest.mark.slow
def test_unplug_and_replug(rig: Rig) -> None:
    rig.ready()
    assert rig.command(1, mode=convert.MODE_BEAM, x=0.3, width=0.2).info == ''
    rig.grbl.unplug()
    assert rig.run_until(lambda: rig.controller.phase == 'offline')
    assert any('link down' in w for w in rig.transport.warnings)
    lost = rig.command(2, mode=convert.MODE_BEAM, x=0.4, width=0.2)
    assert 'gantry not ready' in lost.info and 'link lost' in lost.info
    status = rig.transport.messages('gantry/status')[-1].status[0]
    assert dict((kv.key, kv.value) for kv in status.values)['link'] == 'offline'
    rig.grbl.replug()  # same path, a fresh controller at 0,0,0 with its banner
    assert rig.run_until(lambda: rig.controller.ready, timeout=5.0)
    assert rig.command(3, mode=convert.MODE_BEAM, x=0.4, width=0.2).info == ''
    assert rig.grbl.mpos[0] == pytest.approx(-845.0 + 400.0, abs=0.05)


def test_settings_that_contradict_the_calibration_move_nothing(tmp_path) -> None:
    rig = Rig(tmp_path, settings={32: 0})
    try:
        assert rig.run_until(lambda: rig.controller.phase == 'fault')
        assert '$32 = 0 (laser mode off)' in rig.controller.fault
        refused = rig.command(1, mode=convert.MODE_BEAM, x=0.4, width=0.2)
        assert 'laser mode off' in refused.info
        assert jogs(rig.grbl) == []
    finally:
        rig.close()


def test_refused_line_fails_the_step(rig: Rig) -> None:
    rig.ready()
    assert rig.run_until(lambda: 'M5' in rig.grbl.lines)
    rig.grbl.reject_next.append(15)  # e.g. a jog beyond the controller's own soft limits
    result = rig.command(1, mode=convert.MODE_BEAM, x=0.4, width=0.2)
    assert 'error:15' in result.info and 'exceeds machine travel' in result.info


def test_shutdown_turns_the_lamp_off_and_leaves_the_machine_idle(rig: Rig) -> None:
    rig.ready()
    rig.transport.inject('light/command', types.new(
        types.LIGHT_COMMAND, step_id=1, mode=convert.MODE_BEAM, x=0.8, width=0.2))
    assert rig.run_until(lambda: rig.grbl.state == 'Jog')
    rig.node.close()
    assert rig.grbl.spindle[0] == 'M5'
    assert rig.grbl.state in ('Idle', 'Alarm')
    assert rig.results()[-1].step_id == 1 and 'shutting down' in rig.results()[-1].info


def test_a_refused_reset_changes_nothing(tmp_path) -> None:
    """A reset whose light is out of the travel is refused and leaves the light model as it
    was: the next unseeded reset is the simulator's after the accepted resets only."""
    rig = Rig(tmp_path, cal=load_cal(x={'axis': 'X', 'mm_per_m': 1000.0, 'offset_mm': -845.0,
                                        'direction': 1, 'min_mm': -600.0, 'max_mm': -5.0}))
    try:
        rig.ready()

        def configs() -> list[Any]:
            return rig.transport.messages('chamber/config')

        def reset(reset_id: int, seed: int | None) -> Any:
            before = len(rig.results())
            rig.transport.inject('reset', types.new(
                types.RESET_REQUEST, reset_id=reset_id, has_seed=seed is not None,
                seed=seed or 0))
            assert rig.run_until(lambda: len(rig.results()) > before, timeout=10.0)
            return rig.results()[-1]

        assert reset(1, 1).info == ''  # light at x = 0.72 m: inside [0.245, 0.84]
        published = len(configs())
        refused = reset(2, 10)  # light at x = 0.22 m
        assert 'outside its travel' in refused.info and len(configs()) == published
        assert reset(3, None).info == ''
        sim = Simulation(SimConfig())
        sim.reset(seed=1)
        sim.reset(seed=None)
        config = json.loads(configs()[-1].data)
        assert (config['reset_id'], config['episode']) == (3, sim.episode + 1)  # + start-up
        assert config['target'] == {'x': sim.chamber.target.real, 'z': sim.chamber.target.imag}
        assert rig.grbl.mpos[0] == pytest.approx(-845.0 + 1000.0 * sim.chamber.light.x, abs=0.05)
    finally:
        rig.close()
