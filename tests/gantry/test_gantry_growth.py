"""A lockstep step's growth period on the rig (issue 31, items 1 and 2), against the emulator.

After the move the lamp stays on at the target for ``growth_s`` of lit time, then the step is
answered (photographed, with a camera): the answer shows the plant grown under this step's
light, as the simulator's ``s_{t+1}``. Faults, an e-stop or a newer command end the period by
the safety rules; the lamp follows the photoperiod, and a growth period counts lit time only.
Tests wait on events (the answer, the status, the port); the photoperiod's clock is the test's.
"""

from __future__ import annotations

import calendar
import time
from typing import Any

import pytest

from growspace_sim.ros import types
from test_gantry_node import Rig
from test_gantry_safety import beam, call, place, status

pytestmark = pytest.mark.slow  # each test drives the GRBL emulator for about 1 s

GROWTH_S = 0.4
LAMP_ON = ('M3', 1000.0)
NIGHT = calendar.timegm((2026, 3, 2, 23, 0, 0))  # 23:00 UTC: lights 06:00-22:00 are off
MORNING = calendar.timegm((2026, 3, 3, 6, 0, 0))


class Wall:
    """A UTC clock that runs in real time from where the test puts it."""

    def __init__(self, start: float) -> None:
        self.jump_to(start)

    def jump_to(self, t: float) -> None:
        self.offset = t - time.monotonic()

    def __call__(self) -> float:
        return time.monotonic() + self.offset


def answered(rig: Rig, step_id: int) -> Any:
    """The step_result of ``step_id``, or None."""
    return next((r for r in rig.results() if r.step_id == step_id), None)


def step_phase(rig: Rig) -> str:
    return status(rig)[2]['step']


def test_a_step_grows_under_its_light_before_it_is_answered(tmp_path) -> None:
    """Move, then the lamp on at the target for growth_s, then the answer; the status says
    the phase and the time left; the watchdog (shorter than the period) does not trip; a reset
    has no growth period."""
    rig = Rig(tmp_path, growth_s=GROWTH_S, watchdog_s=0.1)
    try:
        rig.ready()
        place(rig)  # a reset: answered once placed
        assert all(v.value != 'growing' for m in rig.transport.messages('gantry/status')
                   for v in m.status[0].values if v.key == 'step')
        rig.transport.inject('light/command', beam(0.5, step_id=1))
        assert rig.run_until(lambda: step_phase(rig) == 'growing')
        grew_from = time.monotonic()
        values = status(rig)[2]
        assert 0.0 < float(values['growth_left_s']) <= GROWTH_S and values['lights'] == 'on'
        assert answered(rig, 1) is None and rig.controller.reached()
        assert rig.grbl.spindle == LAMP_ON
        assert rig.run_until(lambda: answered(rig, 1) is not None)
        assert time.monotonic() - grew_from >= GROWTH_S - 0.05  # the status came first
        assert answered(rig, 1).info == '' and answered(rig, 1).step == 1
        assert not any('watchdog' in w for w in rig.transport.warnings)
        assert rig.run_until(lambda: step_phase(rig) == '')
    finally:
        rig.close()


@pytest.mark.parametrize('cause, reason', [
    ('estop', 'emergency stop'), ('newer', 'superseded'), ('alarm', 'hard limit'),
    ('unplug', 'link lost')])
def test_a_fault_an_estop_or_a_newer_command_ends_the_growth_period(tmp_path, cause,
                                                                     reason) -> None:
    rig = Rig(tmp_path, growth_s=60.0, watchdog_s=0.0)  # only the cause can end it
    try:
        rig.ready()
        place(rig)
        rig.transport.inject('light/command', beam(0.5, step_id=1))
        assert rig.run_until(lambda: step_phase(rig) == 'growing')
        if cause == 'estop':
            assert call(rig, 'gantry/estop').success
        elif cause == 'newer':
            rig.transport.inject('light/command', beam(0.3, step_id=2))
        elif cause == 'alarm':
            rig.grbl.trigger_alarm(1)
        else:
            rig.grbl.unplug()
        assert rig.run_until(lambda: answered(rig, 1) is not None)
        assert 'error' in answered(rig, 1).info and reason in answered(rig, 1).info
        assert len([r for r in rig.results() if r.step_id == 1]) == 1
        assert answered(rig, 1).step == 0  # not counted: the agent redoes it, same number
        if cause == 'newer':  # the newer step moves and grows in its turn
            assert rig.run_until(lambda: step_phase(rig) == 'growing' and answered(rig, 2)
                                 is None and rig.controller.reached())
            return
        assert rig.controller.lamp_s == 0.0 and step_phase(rig) == ''
        if cause != 'unplug':  # GRBL's spindle output goes off (a reset, mc_reset)
            assert rig.run_until(lambda: rig.grbl.spindle[0] == 'M5')
    finally:
        rig.close()


def test_growth_counts_only_lit_time_and_the_lamp_waits_for_the_morning(tmp_path) -> None:
    """A step moved at night grows nothing until lights_on: lamp off, status 'night'; in the
    morning the lamp goes on and the step ends after growth_s of light."""
    wall = Wall(NIGHT)
    rig = Rig(tmp_path, growth_s=GROWTH_S, lights_on='06:00', lights_off='22:00',
              wall_clock=wall)
    try:
        rig.ready()
        place(rig)  # at night: placed, lamp off
        rig.transport.inject('light/command', beam(0.5, step_id=1))
        assert rig.run_until(lambda: step_phase(rig) == 'growing, night: lamp off')
        values = status(rig)[2]
        assert values['lights'] == 'off (night)'
        assert float(values['growth_left_s']) == pytest.approx(GROWTH_S, abs=0.01)
        assert float(values['growth_ends_in_s']) == pytest.approx(7 * 3600 + GROWTH_S, abs=5)
        assert not [line for line in rig.grbl.lines if line.startswith('M3')]
        assert rig.grbl.spindle[0] == 'M5' and answered(rig, 1) is None
        wall.jump_to(MORNING)
        assert rig.run_until(lambda: rig.grbl.spindle == LAMP_ON)
        lit_at = time.monotonic()
        assert rig.run_until(lambda: answered(rig, 1) is not None)
        assert time.monotonic() - lit_at >= GROWTH_S - 0.1
        assert answered(rig, 1).info == ''
    finally:
        rig.close()


def test_the_lamp_follows_the_photoperiod_in_realtime(tmp_path) -> None:
    wall = Wall(NIGHT)
    rig = Rig(tmp_path, mode='realtime', watchdog_s=0.0, lights_on='22:30',
              lights_off='06:00', wall_clock=wall)  # across midnight: off at 23:00 + 0 h
    try:
        wall.jump_to(NIGHT - 3600.0)  # 22:00: before lights_on
        rig.ready()
        rig.transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=1, has_seed=True,
                                                seed=11))
        assert rig.run_until(lambda: rig.controller.reached())
        assert rig.grbl.spindle[0] == 'M5'
        wall.jump_to(NIGHT)  # 23:00: lit
        assert rig.run_until(lambda: rig.grbl.spindle == LAMP_ON)
        wall.jump_to(MORNING)  # 06:00: off
        assert rig.run_until(lambda: rig.grbl.spindle[0] == 'M5')
        assert status(rig)[2]['lights'] == 'off (night)'
    finally:
        rig.close()


def test_step_time_on_a_clock_of_its_own() -> None:
    """The growth period's rules without a machine: none for a reset or growth_s 0; it ends
    when the lit time is done; the phase and time left say where it is."""
    from growspace_gantry.growth import GROWING, NIGHT as NIGHT_PHASE, StepTime
    from growspace_sim.core.photoperiod import Photoperiod

    now = [NIGHT - 1800.0]  # 22:30: night
    grow = StepTime(3600.0, Photoperiod('06:00', '22:00'), lambda: now[0])
    assert not StepTime(0.0, Photoperiod(), lambda: now[0]).start(1, 1)
    assert not grow.start(1, 0) and not grow.busy  # a reset grows nothing
    assert grow.lamp_s(1000.0) == 0.0 and grow.phase() == ''
    assert grow.start(1, 4) and grow.busy and grow.phase() == NIGHT_PHASE
    assert grow.left() == pytest.approx((3600.0, 7.5 * 3600.0 + 3600.0))
    now[0] = MORNING + 1800.0
    assert grow.phase() == GROWING and grow.lamp_s(1000.0) == 1000.0
    assert grow.left() == pytest.approx((1800.0, 1800.0)) and grow.poll() is None
    now[0] = MORNING + 3600.0
    done = grow.poll()
    assert (done.reset_id, done.step_id, done.end) == (1, 4, MORNING + 3600.0)
    assert not grow.busy and grow.left() == (0.0, 0.0) and grow.abandon() is None
    assert grow.start(2, 1) and grow.abandon().step_id == 1 and not grow.busy
