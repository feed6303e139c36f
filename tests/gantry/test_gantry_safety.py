"""The gantry's safety rules against the GRBL emulator: what must never move or light up.

Each test reproduces a fault seen on GRBL 1.1h's own firmware (issue 23): a stale move resumed
after a lost link, a restart or an unlock; a jog cancel lost because it overtook its jog; a
light model that drifted from the machine; an e-stop the controller forgot; damaged status
lines; a watchdog that cut long moves; a status that said what was not true.
"""

from __future__ import annotations

import re
import time
from typing import Any

import numpy as np
import pytest

from grbl_emulator import random_damage
from growspace_gantry.motion import SETTLED_REPORTS
from growspace_sim.ros import convert, types
from test_gantry_node import jogs, load_cal, Rig, RIG as RIG_SETTINGS

TRIGGER = 'std_srvs/srv/Trigger_Request'
X0_MM = -845.0  # machine X of chamber x = 0 (the shipped calibration)


def beam(x: float, width: float = 0.2, step_id: int = 0) -> Any:
    return types.new(types.LIGHT_COMMAND, step_id=step_id, mode=convert.MODE_BEAM, x=x,
                     width=width)


def act(action: int, step_id: int = 0) -> Any:
    return types.new(types.LIGHT_COMMAND, step_id=step_id, mode=convert.MODE_DISCRETE,
                     action=action)


LEFT, RIGHT, STAY = 0, 1, 2  # beam actions


def call(rig: Rig, service: str) -> Any:
    return rig.transport.services[service](types.new(TRIGGER))


def settle(rig: Rig, seconds: float) -> None:
    rig.run_until(lambda: False, timeout=seconds)


def status(rig: Rig) -> tuple[int, str, dict[str, str]]:
    s = rig.transport.messages('gantry/status')[-1].status[0]
    return s.level, s.message, {kv.key: kv.value for kv in s.values}


def place(rig: Rig, reset_id: int = 1, seed: int = 11) -> None:
    """A reset: the light placed where the task starts it (the position is established)."""
    before = len(rig.results())
    rig.transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=reset_id,
                                            has_seed=True, seed=seed))
    assert rig.run_until(lambda: len(rig.results()) > before), rig.transport.warnings
    assert rig.results()[-1].info == '', rig.results()[-1].info


def moves_after(rig: Rig, mark: int) -> list[str]:
    """Lines after ``mark`` that move the machine or light the lamp."""
    return [line for line in rig.grbl.lines[mark:] if line.startswith(('$J', 'M3', 'G0', 'G1'))]


@pytest.fixture
def realtime(tmp_path):
    rig = Rig(tmp_path, mode='realtime', watchdog_s=60.0)
    yield rig
    rig.close()


# --- 1. no stale move ever resumes ------------------------------------------------------------

@pytest.mark.parametrize('mode', ['realtime', 'lockstep'])
@pytest.mark.slow
def test_after_a_lost_link_nothing_moves_until_a_new_command(tmp_path, mode) -> None:
    rig = Rig(tmp_path, mode=mode, watchdog_s=60.0)
    try:
        rig.ready()
        place(rig)
        rig.transport.inject('light/command', beam(0.8, step_id=1 if mode == 'lockstep' else 0))
        assert rig.run_until(lambda: rig.grbl.state == 'Jog')
        rig.grbl.unplug()
        assert rig.run_until(lambda: rig.controller.phase == 'offline')
        if mode == 'lockstep':
            assert 'link lost' in rig.results()[-1].info
        mark = len(rig.grbl.lines)
        rig.grbl.replug()  # a fresh controller at MPos 0,0,0
        assert rig.run_until(lambda: rig.controller.ready and rig.controller.status is not None)
        settle(rig, 0.5)
        assert moves_after(rig, mark) == []
        assert rig.grbl.spindle[0] == 'M5' and rig.grbl.mpos == (0.0, 0.0, 0.0)
        # The position is gone: a relative action is refused, saying how to get it back.
        rig.transport.inject('light/command', act(RIGHT, step_id=2 if mode == 'lockstep' else 0))
        settle(rig, 0.1)
        assert moves_after(rig, mark) == []
        assert any('re-established' in w for w in rig.transport.warnings)
        # A new absolute command moves and lights again.
        rig.transport.inject('light/command', beam(0.4, step_id=3 if mode == 'lockstep' else 0))
        assert rig.run_until(lambda: rig.controller.reached() and rig.grbl.spindle[0] == 'M3')
        assert rig.grbl.mpos[0] == pytest.approx(X0_MM + 400.0, abs=0.05)
    finally:
        rig.close()


@pytest.mark.slow
def test_a_controller_restart_clears_the_target_and_asks_for_the_position(realtime) -> None:
    rig = realtime
    rig.ready()
    place(rig)
    rig.transport.inject('light/command', beam(0.8))
    assert rig.run_until(lambda: rig.grbl.state == 'Jog')
    mark = len(rig.grbl.lines)
    rig.grbl.restart()  # a power glitch: banner, MPos 0,0,0, lamp off
    assert rig.run_until(lambda: rig.grbl.lines.count('$$') == 2 and rig.controller.ready)
    settle(rig, 0.5)
    assert moves_after(rig, mark) == [] and rig.grbl.spindle[0] == 'M5'
    level, message, values = status(rig)
    assert 'position' in message and 're-established' in message and level >= 1
    rig.transport.inject('light/command', act(RIGHT))
    settle(rig, 0.1)
    assert moves_after(rig, mark) == []
    place(rig, reset_id=2)  # a reset places the light: relative actions work again
    x = rig.grbl.mpos[0]
    rig.transport.inject('light/command', act(RIGHT))
    assert rig.run_until(lambda: rig.grbl.mpos[0] > x + 49.0 and rig.controller.reached())


@pytest.mark.slow
def test_unlock_never_starts_a_move(realtime) -> None:
    rig = realtime
    rig.ready()
    place(rig)
    rig.transport.inject('light/command', beam(0.8))
    assert rig.run_until(lambda: rig.grbl.state == 'Jog')
    rig.grbl.trigger_alarm(1)
    assert rig.run_until(lambda: rig.controller.alarm == 1)
    stopped_at, mark = rig.grbl.mpos, len(rig.grbl.lines)
    assert call(rig, 'gantry/unlock').success
    assert rig.run_until(lambda: rig.grbl.state == 'Idle')
    settle(rig, 0.5)
    assert rig.grbl.lines[mark:].count('$X') == 1 and moves_after(rig, mark) == []
    assert rig.grbl.mpos == stopped_at and rig.grbl.spindle[0] == 'M5'


# --- 2. jog cancel the way GRBL does -----------------------------------------------------------

@pytest.mark.slow
def test_a_flood_of_commands_ends_on_the_newest_and_no_superseded_jog_runs_out(tmp_path) -> None:
    """200 commands in 2 s across the chamber: every cancel reaches a running jog, the lamp
    ends on the newest command, and a superseded jog stops within a status period or two."""
    rig = Rig(tmp_path, mode='realtime', watchdog_s=0.0, status_hz=50.0)
    try:
        rig.ready()
        place(rig)
        rig.grbl.speedup = 10.0  # far jogs take seconds: there is always one to cancel
        rng = np.random.default_rng(3)
        xs = [round(float(x), 4) for x in np.where(np.arange(200) % 2, rng.uniform(
            0.1, 0.3, 200), rng.uniform(0.55, 0.75, 200))]
        sent = []
        for x in xs:
            rig.transport.inject('light/command', beam(x))
            sent.append(time.monotonic())
            rig.run_until(lambda: False, timeout=0.01)
        assert rig.run_until(lambda: rig.controller.reached(), timeout=15.0)
        assert rig.grbl.mpos[0] == pytest.approx(X0_MM + 1000.0 * xs[-1], abs=0.05)
        assert rig.grbl.spindle == ('M3', 1000.0)
        # Every cancel met a running jog, or crossed its end on the wire ('late'): none came
        # before its jog was parsed ('early'), none was a second one ('repeat').
        assert rig.grbl.cancels and not {'early', 'ignored', 'repeat'} & set(
            rig.grbl.cancels), rig.grbl.cancels
        index = {round(X0_MM + 1000.0 * x, 1): i for i, x in enumerate(xs)}
        for jog in rig.grbl.jogs[:-1]:
            if jog['outcome'] == 'done' and jog['end'] is not None:
                i = index.get(round(jog['target'][0], 1))  # None: the reset's jog
                # superseded: it may only end by itself very soon
                if i is not None and i + 1 < len(sent):
                    assert jog['end'] - sent[i + 1] < 0.25, (jog, i)
        assert rig.grbl.jogs[-1]['outcome'] == 'done'
    finally:
        rig.close()


# --- 3. relative actions apply to the light the machine reached ---------------------------------

def test_refused_commands_leave_the_light_where_the_machine_is(tmp_path) -> None:
    rig = Rig(tmp_path)
    try:
        rig.ready()
        place(rig)
        x0 = rig.grbl.mpos[0]
        rig.grbl.trigger_alarm(2)  # soft limit: the machine keeps its position
        assert rig.run_until(lambda: rig.controller.alarm == 2)
        for step_id in range(1, 5):
            assert 'error' in rig.command(step_id, mode=convert.MODE_DISCRETE,
                                          action=RIGHT).info
        assert call(rig, 'gantry/unlock').success
        assert rig.run_until(lambda: rig.controller.ready and rig.grbl.state == 'Idle')
        # The driver trusts where the machine stands once SETTLED_REPORTS Idle reports agree;
        # a step before that jogs to its target even if the machine is there (a loaded
        # machine sent the step first: a jog of no length, which this test does not allow).
        idle = []  # the Idle reports the controller has read (each is a new status)

        def settled() -> bool:
            status = rig.controller.status
            if status is not None and status.state == 'Idle' and not (idle and idle[-1] is status):
                idle.append(status)
            return len(idle) > SETTLED_REPORTS

        assert rig.run_until(settled)
        mark = len(rig.grbl.lines)
        assert rig.command(5, mode=convert.MODE_DISCRETE, action=STAY).info == ''
        assert [line for line in moves_after(rig, mark) if line.startswith('$J')] == []
        assert rig.grbl.mpos[0] == x0
    finally:
        rig.close()


@pytest.mark.parametrize('mode', ['discrete', 'continuous'])
def test_a_refused_step_leaves_the_light_where_the_machine_is(rig, mode) -> None:
    rig.ready()
    place(rig)
    x0 = rig.grbl.mpos[0]
    right = {'mode': convert.MODE_DISCRETE, 'action': RIGHT} if mode == 'discrete' else \
        {'mode': convert.MODE_CONTINUOUS, 'continuous': [1.0, 0.0]}
    stay = {'mode': convert.MODE_DISCRETE, 'action': STAY} if mode == 'discrete' else \
        {'mode': convert.MODE_CONTINUOUS, 'continuous': [0.0, 0.0]}
    rig.grbl.reject_next.append(15)  # GRBL refuses the jog (its own soft limits)
    assert 'error:15' in rig.command(1, **right).info
    assert rig.command(2, **stay).info == ''
    assert rig.grbl.mpos[0] == pytest.approx(x0, abs=0.05)
    reached = rig.transport.messages('light/state')[-1]
    assert reached.x == pytest.approx((x0 - X0_MM) / 1000.0, abs=1e-4)


@pytest.fixture
def rig(tmp_path):
    r = Rig(tmp_path)
    yield r
    r.close()


# --- 4. the e-stop is latched by the driver ---------------------------------------------------

@pytest.mark.parametrize('reset_alarm, moving', [(True, True), (False, True), (True, False)])
@pytest.mark.slow
def test_the_estop_is_latched_until_a_person_unlocks(tmp_path, reset_alarm, moving) -> None:
    """GRBL came back Idle after 2 of 6 mid-move e-stops and after every idle one: the driver
    refuses every command until gantry/unlock, whatever GRBL reports."""
    rig = Rig(tmp_path, emulator={'reset_alarm': reset_alarm})
    try:
        rig.ready()
        place(rig)
        if moving:
            rig.transport.inject('light/command', beam(0.8, step_id=1))
            assert rig.run_until(lambda: rig.grbl.state == 'Jog')
        assert call(rig, 'gantry/estop').success
        assert rig.run_until(lambda: rig.grbl.lines.count('$$') == 2
                             and rig.controller.phase == 'ready' and rig.controller.status)
        assert rig.grbl.state == ('Alarm' if reset_alarm and moving else 'Idle')
        assert any('refuses every command until gantry/unlock' in w
                   for w in rig.transport.warnings), rig.transport.warnings
        mark = len(rig.grbl.lines)
        refused = rig.command(2, mode=convert.MODE_BEAM, x=0.5, width=0.2)
        assert 'e-stop' in refused.info and 'gantry/unlock' in refused.info
        rig.transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=9, has_seed=True,
                                                seed=3))
        assert rig.run_until(lambda: rig.results()[-1].reset_id == 9)
        assert 'e-stop' in rig.results()[-1].info
        settle(rig, 0.3)
        assert moves_after(rig, mark) == [] and '$X' not in rig.grbl.lines
        level, message, _ = status(rig)
        assert level == 2 and 'e-stop' in message
        assert call(rig, 'gantry/unlock').success
        assert rig.run_until(lambda: rig.grbl.state == 'Idle')
        settle(rig, 0.2)
        assert moves_after(rig, mark) == []  # unlocking moves nothing
        assert rig.command(3, mode=convert.MODE_BEAM, x=0.5, width=0.2).info == ''
    finally:
        rig.close()


# --- 5. damaged status lines ---------------------------------------------------------------------

def damage_three_ways(every: int) -> Any:
    """Every ``every``-th status line: a random byte flipped/dropped/inserted, or the last
    coordinate dropped (two coordinates), or X's hundreds digit changed (still well formed)."""
    randomly = random_damage(1, seed=5)
    count = 0

    def damage(line: str) -> str | None:
        nonlocal count
        count += 1
        if count % every:
            return None
        kind = (count // every) % 3
        if kind == 0:
            return randomly(line)
        if kind == 1:
            return re.sub(r'(Pos:[^,|>]*,[^,|>]*),[^|>]*', r'\1', line)
        return re.sub(r'Pos:-(\d)', lambda m: f'Pos:-{(int(m.group(1)) + 2) % 10}', line)
    return damage


@pytest.mark.slow
def test_damaged_status_lines_neither_raise_nor_move_the_machine(tmp_path) -> None:
    rig = Rig(tmp_path, emulator={'damage': damage_three_ways(every=3)})
    try:
        rig.ready()
        place(rig)
        moved = 0
        for step_id, action in enumerate((RIGHT, RIGHT, STAY, LEFT, 3, 4, STAY, LEFT), 1):
            before = rig.transport.messages('light/state')[-1]
            assert rig.command(step_id, mode=convert.MODE_DISCRETE, action=action).info == ''
            after = rig.transport.messages('light/state')[-1]
            moved += (abs(after.x - before.x) > 1e-4) or (abs(after.width - before.width) > 1e-4)
            assert after.x == pytest.approx((rig.grbl.mpos[0] - X0_MM) / 1000.0, abs=1e-4)
        assert len(rig.grbl.damaged) >= 10
        assert len(jogs(rig.grbl)) == moved + 1  # the reset's and one per moving step
    finally:
        rig.close()


# --- 6. the watchdog -----------------------------------------------------------------------------

@pytest.mark.slow
def test_a_long_move_is_not_cut_by_the_watchdog(tmp_path) -> None:
    rig = Rig(tmp_path, mode='realtime', watchdog_s=0.3)
    try:
        rig.ready()
        place(rig)
        rig.grbl.speedup = 12.0  # 1000 mm/min x 12: the move below takes ~1.5 s
        mark = len(rig.grbl.lines)
        rig.transport.inject('light/command', beam(0.1 if rig.grbl.mpos[0] > -500 else 0.8))
        assert rig.run_until(lambda: rig.controller.reached(), timeout=10.0)
        assert 'M5' not in rig.grbl.lines[mark:] and rig.grbl.spindle[0] == 'M3'
        assert rig.run_until(lambda: rig.grbl.spindle[0] == 'M5', timeout=2.0)
        assert any('watchdog' in w for w in rig.transport.warnings)
    finally:
        rig.close()


@pytest.mark.slow
def test_refused_commands_do_not_feed_the_watchdog(tmp_path) -> None:
    # The node's clock stops once the lamp is lit and then goes on by hand, a tenth of the
    # watchdog per refused command: a slow machine cannot leave a gap that trips it anyway.
    clock = StoppableClock()
    rig = Rig(tmp_path, mode='realtime', watchdog_s=0.4, clock=clock, cal=load_cal(x={
        'axis': 'X', 'mm_per_m': 1000.0, 'offset_mm': -845.0, 'direction': 1,
        'min_mm': -845.0, 'max_mm': -245.0}))
    try:
        rig.ready()
        place(rig, seed=2)
        for _ in range(3):  # (until the clock stops before the watchdog trips by itself)
            rig.transport.inject('light/command', beam(0.3))
            assert rig.run_until(lambda: rig.controller.reached()
                                 and rig.grbl.spindle[0] == 'M3')
            clock.stop()
            if not rig.node.safety.watchdog_tripped:
                break
            clock.go_on()
        assert not rig.node.safety.watchdog_tripped
        warnings, mark = len(rig.transport.warnings), len(rig.grbl.lines)
        steps = 0  # of 0.04 s, a refused command each
        while steps < 50 and rig.grbl.spindle[0] == 'M3':  # 5 watchdog periods at most
            rig.transport.inject('light/command', beam(0.8))  # beyond the travel: refused
            clock.step(0.04)
            steps += 1
            rig.run_until(lambda: rig.grbl.spindle[0] == 'M5', timeout=0.05)
        assert rig.node.safety.watchdog_tripped and rig.grbl.spindle[0] == 'M5'
        assert steps <= 11, steps  # tripped on time (0.4 s after the move), as if none came
        assert any('not sent to the machine' in w for w in rig.transport.warnings[warnings:])
        assert moves_after(rig, mark) == []
    finally:
        rig.close()


class StoppableClock:
    """``time.monotonic`` until stopped; then it moves only when a test steps it."""

    def __init__(self) -> None:
        self.stopped_at: float | None = None

    def __call__(self) -> float:
        return time.monotonic() if self.stopped_at is None else self.stopped_at

    def stop(self) -> None:
        self.stopped_at = time.monotonic()

    def step(self, seconds: float) -> None:
        assert self.stopped_at is not None
        self.stopped_at += seconds

    def go_on(self) -> None:
        self.stopped_at = None


# --- 7. status says what is true -----------------------------------------------------------------

@pytest.mark.slow
def test_status_says_what_is_true(tmp_path) -> None:
    rig = Rig(tmp_path, settings={22: 1})  # homing enabled: GRBL powers up in Alarm, no code
    try:
        assert rig.run_until(lambda: rig.controller.status is not None
                             and rig.controller.status.state == 'Alarm')
        assert rig.run_until(lambda: 'alarm' in status(rig)[1])  # the status that says so
        level, message, values = status(rig)
        assert level == 2 and 'alarm (no code)' in message and 'ALARM:0' not in message
        assert values['lamp_s'] == '0'
        assert call(rig, 'gantry/unlock').success
        assert rig.run_until(lambda: rig.controller.ready and rig.grbl.state == 'Idle')
        assert rig.command(1, mode=convert.MODE_BEAM, x=0.5, width=0.2).info == ''
        assert rig.run_until(lambda: status(rig)[2]['lamp_s'] == '1000')
        level, message, values = status(rig)
        assert (level, values['lamp_s'], values['last_failure']) == (0, '1000', '')
        rig.grbl.trigger_alarm(3)
        assert rig.run_until(lambda: rig.controller.alarm == 3 and status(rig)[0] == 2)
        level, message, values = status(rig)
        assert level == 2 and message.count('ALARM:3') == 1
        rig.grbl.unplug()
        assert rig.run_until(lambda: rig.controller.phase == 'offline')
        assert rig.run_until(lambda: status(rig)[2]['lamp_s'] == 'unknown')
        for s in (m.status[0] for m in rig.transport.messages('gantry/status')):
            values = {kv.key: kv.value for kv in s.values}
            if s.level == 0:  # OK only with a report in hand and no alarm
                assert values['state'] in ('Idle', 'Jog', 'Run'), values
    finally:
        rig.close()


def test_suppressed_warnings_are_counted_in_the_log(tmp_path) -> None:
    rig = Rig(tmp_path, cal=load_cal(x={'axis': 'X', 'mm_per_m': 1000.0, 'offset_mm': -845.0,
                                        'direction': 1, 'min_mm': -600.0, 'max_mm': -5.0}))
    try:
        rig.ready()
        for step_id in range(1, 5):
            assert 'outside its travel' in rig.command(step_id, mode=convert.MODE_BEAM, x=0.1,
                                                       width=0.2).info
        refused = [w for w in rig.transport.warnings if 'outside its travel' in w]
        assert len(refused) == 1  # throttled
        rig.transport.time_s += 10.0  # the throttle period passes, no fifth command
        assert rig.run_until(lambda: any('3 similar warnings suppressed' in w
                                         for w in rig.transport.warnings)), \
            rig.transport.warnings
    finally:
        rig.close()


def test_an_error_inside_the_poll_never_raises_and_stops_the_machine(rig, monkeypatch) -> None:
    """The timer callback must not raise: a driver in an unknown state is e-stopped and
    latched until a person looks."""
    rig.ready()
    place(rig)

    def broken(now: float) -> list:
        raise KeyError('Z')
    monkeypatch.setattr(rig.controller, 'poll', broken)
    rig.node.poll()  # no exception
    monkeypatch.undo()
    assert rig.node.safety.estop_latched
    assert any('internal error' in w and "KeyError: 'Z'" in w for w in rig.transport.warnings)
    assert rig.run_until(lambda: held_reset(rig))


def held_reset(rig: Rig) -> bool:
    return bytes([0x21, 0x18]) in bytes(b for b in rig.grbl.realtime if b != 0x3F)


def test_homing_waits_for_the_estop_latch_to_be_released(tmp_path) -> None:
    rig = Rig(tmp_path, settings={22: 1})
    try:
        assert rig.run_until(lambda: rig.controller.alarm == 0)
        assert call(rig, 'gantry/estop').success
        refused = call(rig, 'gantry/home')
        assert not refused.success and 'e-stop latched' in refused.message
        assert '$H' not in rig.grbl.lines
        assert rig.run_until(lambda: rig.controller.phase == 'ready' and rig.controller.status)
        assert call(rig, 'gantry/unlock').success  # releases the latch and sends $X
        assert rig.run_until(lambda: rig.grbl.state == 'Idle'
                             and not rig.controller.counter.pending)  # $X answered
        homed = call(rig, 'gantry/home')
        assert homed.success, (homed.message, rig.controller.phase, rig.controller.status)
        assert rig.run_until(lambda: rig.node.safety.position_known)  # homing establishes it
        assert rig.grbl.lines.count('$H') == 1
    finally:
        rig.close()


# --- 6. a fault stops the machine in every motion state, by GRBL's own rules ---------------------

def realtime_bytes(grbl, mark: int) -> list[int]:
    """The real-time bytes after ``mark`` but status requests, repeats merged."""
    sent = [b for b in grbl.realtime[mark:] if b != 0x3F]
    return [b for i, b in enumerate(sent) if i == 0 or b != sent[i - 1]]


def test_the_emulator_restarts_a_starved_jog_as_a_cycle_that_only_a_hold_stops(tmp_path) -> None:
    """GRBL 1.1 (protocol.c, stepper.c, motion_control.c, gcode.c): a starved segment buffer
    during a jog ends in ``Run`` (auto cycle start); a jog cancel is then ignored; ``M5`` waits
    for the planner to empty; a feed hold decelerates (``Hold:1``) and stops (``Hold:0``); a
    reset at ``Hold:0`` keeps the position, no alarm, and switches the spindle off; a reset
    while the hold decelerates is ``ALARM:3``."""
    from grbl_emulator import GrblEmulator
    from growspace_gantry.link import SerialLink
    from waiting import LinkLines

    with GrblEmulator({**RIG_SETTINGS}, speedup=10.0, link_dir=tmp_path) as grbl:
        link = SerialLink(grbl.port)
        lines = LinkLines(link)
        until, seen = lines.until, lines.seen

        def state() -> str:
            return until(lambda x: x.startswith('<'), b'?')[1:].split('|')[0]

        try:
            for reset_at in ('Hold:0', 'Hold:1'):
                link.write(b'\x18')
                until(lambda x: x.startswith('Grbl '))
                if grbl.state == 'Alarm':
                    until(lambda x: x == 'ok', b'$X\n')
                until(lambda x: x == 'ok', b'M3 S500\n')
                until(lambda x: x == 'ok', b'$J=G53 X-800 F1000\n')
                assert state() == 'Jog'
                assert grbl.starve_segment_buffer()
                assert state() == 'Run' and grbl.cycles_from_jogs
                link.write(b'\x85')
                assert state() == 'Run' and grbl.cancels[-1] != 'cancelled'
                answers = len([x for x in seen if x == 'ok'])
                link.write(b'M5\n')  # spindle_sync: waits for the planner to empty
                link.write(b'!')
                if reset_at == 'Hold:1':
                    assert state() == 'Hold:1'
                    link.write(b'\x18')
                    until(lambda x: x == 'ALARM:3')
                    assert grbl.jogs[-1]['outcome'] == 'reset'
                    continue
                while (now := state()) != 'Hold:0':
                    assert now == 'Hold:1'
                held = grbl.mpos
                assert held[0] > -800.0 and grbl.spindle == ('M3', 500.0)  # M5 still waits
                assert len([x for x in seen if x == 'ok']) == answers
                link.write(b'\x18')
                until(lambda x: x.startswith('Grbl '))
                assert len([x for x in seen if x == 'ok']) == answers  # flushed, never run
                assert state() == 'Idle' and grbl.mpos == held and grbl.spindle[0] == 'M5'
                assert grbl.jogs[-1]['outcome'] == 'reset'
            assert not any(line.startswith('ALARM') for line in seen[:-1])
        finally:
            link.close()


def far_beam(rig: Rig) -> float:
    """A beam at the far side of the chamber from the light: a move of ~0.7 m."""
    return 0.1 if rig.grbl.mpos[0] > X0_MM + 450.0 else 0.8


@pytest.mark.slow
@pytest.mark.parametrize('mode', ['lockstep', 'realtime'])
@pytest.mark.parametrize('state', ['Jog', 'Run', 'Hold'])
def test_a_fault_stops_the_machine_in_every_motion_state(tmp_path, mode, state) -> None:
    """Jog: a jog cancel. Run (GRBL restarted the jog as a cycle: a starved segment buffer):
    a jog cancel does nothing there, so a feed hold, then a soft reset once ``Hold:0``. Hold
    (a hold button after that): the reset once stopped. Each time the step fails with the
    reason, the lamp goes off, the rest of the move never runs; after Run or Hold the position
    must be re-established (a relative action is refused, an absolute one moves)."""
    rig = Rig(tmp_path, mode=mode, watchdog_s=60.0)
    lockstep = mode == 'lockstep'
    try:
        rig.ready()
        place(rig)
        rig.grbl.speedup = 10.0  # a move of seconds: the fault comes mid-move
        answers = len(rig.results())
        rig.transport.inject('light/command', beam(far_beam(rig), step_id=1 if lockstep else 0))
        assert rig.run_until(lambda: rig.grbl.state == 'Jog')
        mark, lines = len(rig.grbl.realtime), len(rig.grbl.lines)
        if state == 'Jog':
            rig.node.safety.fault('a fault injected by the test')
        else:
            assert rig.grbl.starve_segment_buffer()  # GRBL: Jog -> Run
            if state == 'Hold':
                rig.grbl.press_feed_hold()
        assert rig.run_until(lambda: rig.controller.lamp_s == 0.0)
        assert rig.run_until(lambda: rig.grbl.state == 'Idle' and rig.grbl.spindle[0] == 'M5'
                             and rig.controller.ready and not rig.controller.motion.halting,
                             timeout=10.0), (rig.grbl.state, rig.transport.warnings[-3:])
        assert rig.grbl.jogs[-1]['outcome'] == ('cancelled' if state == 'Jog' else 'reset')
        assert realtime_bytes(rig.grbl, mark) == {'Jog': [0x85], 'Run': [0x21, 0x18],
                                                  'Hold': [0x18]}[state]
        assert rig.controller.alarm is None  # a reset at Hold:0 keeps the position: no alarm
        why = 'injected' if state == 'Jog' else f'went {state}'
        if lockstep:
            assert len(rig.results()) == answers + 1
            assert 'error' in rig.results()[-1].info and why in rig.results()[-1].info
        if state != 'Jog':  # the driver found it, and says so
            assert any(why in w for w in rig.transport.warnings), rig.transport.warnings[-3:]
        stopped = rig.grbl.mpos
        settle(rig, 0.3)
        assert rig.grbl.mpos == stopped and moves_after(rig, lines) == []
        assert rig.node.safety.position_known == (state == 'Jog')
        if state != 'Jog':
            rig.transport.inject('light/command', act(RIGHT, step_id=2 if lockstep else 0))
            settle(rig, 0.1)
            assert moves_after(rig, lines) == []
            assert any('re-established' in w for w in rig.transport.warnings)
        rig.transport.inject('light/command', beam(0.5, step_id=3 if lockstep else 0))
        assert rig.run_until(lambda: rig.controller.reached() and rig.grbl.spindle[0] == 'M3',
                             timeout=10.0)
        assert rig.grbl.mpos[0] == pytest.approx(X0_MM + 500.0, abs=0.05)
    finally:
        rig.close()
