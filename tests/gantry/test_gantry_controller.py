"""The GRBL controller against scripted controller lines: byte-exact jog cancels, damaged lines.

An in-memory link (no port, no thread) feeds the controller the lines GRBL would print and
records every byte the controller writes, so the order of ``ok``, ``Jog`` and ``0x85`` is
decided by the test, not by timing.
"""

from __future__ import annotations

import random

import pytest

from grbl_emulator import DEFAULTS
from growspace_gantry import grbl
from growspace_gantry.controller import GrblController, Log
from test_gantry_node import load_cal, RIG

BANNER = "Grbl 1.1h ['$' for help]"
PERIOD_S = 0.1  # status period of these controllers [s]


class ScriptedLink:
    """A link whose incoming lines the test writes; everything written is kept."""

    def __init__(self) -> None:
        self.written = bytearray()
        self.incoming: list[str] = []

    def write(self, data: bytes) -> None:
        self.written += data

    def read_lines(self) -> list[str]:
        lines, self.incoming = self.incoming, []
        return lines

    def close(self) -> None:
        pass

    def take(self) -> bytes:
        """What was written since the last call."""
        data, self.written = bytes(self.written), bytearray()
        return data


class Script:
    """A controller on a scripted link, brought to the ready state at machine position P."""

    def __init__(self, x: float = -425.0, z: float = -300.0) -> None:
        self.link = ScriptedLink()
        self.warnings: list[str] = []
        self.controller = GrblController(lambda: self.link, load_cal(),
                                         Log(lambda key, text: self.warnings.append(text),
                                             lambda text: None), PERIOD_S)
        self.now = 0.0
        self.pos = (x, 0.0, z)
        self.poll()
        assert self.link.take() == grbl.SOFT_RESET
        self.feed(BANNER)
        assert self.link.take() == b'$$\n'
        settings = {**DEFAULTS, **RIG}
        self.feed(*(f'${n}={v:g}' for n, v in sorted(settings.items())), 'ok')
        self.idle()
        self.idle()
        self.answer_lines()
        self.link.take()

    def poll(self, dt: float = 0.0) -> list:
        self.now += dt
        return self.controller.poll(self.now)

    def feed(self, *lines: str, dt: float = 0.01) -> list:
        self.link.incoming.extend(lines)
        return self.poll(dt)

    def report(self, state: str = 'Idle', pos: tuple[float, ...] | None = None,
               dt: float = PERIOD_S) -> list:
        self.pos = pos or self.pos
        x, y, z = self.pos
        return self.feed(f'<{state}|MPos:{x:.3f},{y:.3f},{z:.3f}|FS:0,0>', dt=dt)

    def idle(self) -> list:
        return self.report('Idle')

    def answer_lines(self) -> list[str]:
        """Answer every line written since the last call with ok; returns them."""
        lines = [line for line in self.link.written.decode('ascii', 'replace').split('\n')
                 if line and not set(line) <= {'?'}]
        self.feed(*(['ok'] * len(lines)))
        return [line.replace('?', '') for line in lines]


def test_a_jog_is_cancelled_only_once_grbl_accepted_it_and_is_jogging() -> None:
    """GRBL ignores 0x85 unless it is in the Jog state: the cancel waits for the jog's ok and
    a Jog report, then the driver waits for Idle before it sends the newest target."""
    s = Script()
    c = s.controller
    c.goto({'X': -100.0, 'Z': -300.0})
    c.set_lamp(1000.0)
    s.poll()
    assert s.answer_lines() == ['M3 S1000']
    s.idle()
    written = s.link.take()
    assert b'$J=G21G53X-100.000Z-300.000F1000\n' in written
    c.goto({'X': -700.0, 'Z': -300.0})  # supersedes the jog before GRBL answered it
    s.poll()
    s.poll(0.001)
    assert grbl.JOG_CANCEL not in s.link.take()  # GRBL would ignore it: not yet jogging
    s.feed('ok')
    assert grbl.JOG_CANCEL not in s.link.written  # accepted, but no Jog report yet
    s.report('Jog', (-420.0, 0.0, -300.0), dt=0.005)
    assert s.link.take().count(grbl.JOG_CANCEL) == 1
    s.report('Jog', (-410.0, 0.0, -300.0))  # still decelerating: no second cancel, no jog
    s.report('Jog', (-405.0, 0.0, -300.0))
    assert s.link.take().replace(b'?', b'') == b''
    s.idle()
    s.idle()
    assert s.link.take().replace(b'?', b'') == b'$J=G21G53X-700.000Z-300.000F1000\n'


@pytest.mark.parametrize('idle_between', [0, 1, 2])
def test_a_jog_grbl_restarts_as_a_cycle_is_held_then_reset_once_stopped(idle_between) -> None:
    """A starved jog goes Run (auto cycle start), maybe through Idle reports on the firmware:
    never a jog cancel there (ignored outside Jog), a feed hold at each Run report, nothing
    while the hold decelerates, a soft reset at Hold:0; the fault says the position is lost;
    never $X."""
    s = Script()
    c = s.controller
    c.goto({'X': -700.0, 'Z': -300.0})
    c.set_lamp(1000.0)
    s.poll()
    assert s.answer_lines() == ['M3 S1000']
    s.idle()
    assert b'$J=' in s.link.take()
    s.feed('ok')
    s.report('Jog', (-450.0, 0.0, -300.0))
    s.link.take()
    for _ in range(idle_between):  # the instant between the starved jog and its cycle
        s.report('Idle', (-460.0, 0.0, -300.0))
    s.answer_lines()  # after two Idle reports short of the target: M5 (GRBL would sync it)
    s.link.take()
    events = s.report('Run', (-470.0, 0.0, -300.0))
    assert s.link.take().replace(b'?', b'') == grbl.FEED_HOLD
    faults = [e for e in events if 'went Run' in e.reason]
    assert len(faults) == 1 and faults[0].position_lost and c.lamp_s == 0.0
    assert c.target is None and c.motion.halting and c.busy
    s.report('Run', (-480.0, 0.0, -300.0))  # the hold not yet acted on: again, harmless
    assert s.link.take().replace(b'?', b'') == grbl.FEED_HOLD
    for pos in (-485.0, -487.0):
        assert not s.report('Hold:1', (pos, 0.0, -300.0))  # decelerating: no new fault
        assert s.link.take().replace(b'?', b'') == b''
    s.report('Hold:0', (-488.0, 0.0, -300.0))
    assert s.link.take().replace(b'?', b'') == grbl.SOFT_RESET and c.phase == 'booting'
    assert not c.motion.halting
    s.feed(BANNER)
    assert s.link.take() == b'$$\n'
    assert grbl.JOG_CANCEL not in s.link.written and b'$X' not in s.link.written


def test_a_jog_that_ends_before_its_cancel_is_not_cancelled() -> None:
    s = Script()
    c = s.controller
    c.goto({'X': -420.0, 'Z': -300.0})
    s.idle()
    s.idle()
    s.feed('ok')
    c.goto({'X': -700.0, 'Z': -300.0})
    s.report('Idle', (-420.0, 0.0, -300.0))  # the short jog ended before a Jog report
    s.report('Idle', (-420.0, 0.0, -300.0))
    written = s.link.take()
    assert grbl.JOG_CANCEL not in written
    assert b'$J=G21G53X-700.000Z-300.000F1000\n' in written


def test_a_status_with_two_coordinates_never_reaches_the_light() -> None:
    s = Script()
    s.feed('<Idle|MPos:-425.000,-300.000|FS:0,0>')
    assert s.controller.position == {'X': -425.0, 'Y': 0.0, 'Z': -300.0}


def test_a_well_formed_jump_the_machine_cannot_make_is_discarded() -> None:
    """``-075.000`` for ``-275.000`` (a real damaged line here) is well formed but 200 mm
    away from a machine that stands still: damage, not motion."""
    s = Script(x=-275.0)
    assert s.controller.position['X'] == -275.0
    s.feed('<Idle|MPos:-075.000,0.000,-300.000|FS:0,0>', dt=PERIOD_S)
    assert s.controller.position['X'] == -275.0
    assert any('implausible' in w for w in s.warnings)
    s.report('Idle', (-274.5, 0.0, -300.0))  # a move the machine could make is taken
    assert s.controller.position['X'] == -274.5


def variants(line: str, rng: random.Random) -> list[str]:
    """Every byte of ``line`` flipped (to a random printable byte), dropped, and a byte
    inserted before it."""
    out = []
    for i in range(len(line) + 1):
        char = chr(rng.randrange(32, 127))
        out.append(line[:i] + char + line[i:])
        if i < len(line):
            out.append(line[:i] + char + line[i + 1:])
            out.append(line[:i] + line[i + 1:])
    return out


VALID = ['ok', 'error:9', 'error:15', 'ALARM:3', BANNER, "[MSG:'$H'|'$X' to unlock]",
         '[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]', '$110=6000', '>G54G21:ok',
         '[MSG:Caution: Unlocked]',
         '<Idle|MPos:-275.000,0.000,-300.000|FS:0,0|WCO:0.000,0.000,0.000>',
         '<Jog|MPos:-275.000,0.000,-300.000|Bf:15,128|FS:1000,1000|A:S>',
         '<Hold:1|MPos:-275.000,0.000,-300.000|FS:0,0|Pn:XZ>',
         '<Alarm|MPos:-275.000,0.000,-300.000|FS:0,0>',
         '<Idle|WPos:-275.000,0.000,-300.000|FS:0,0|Ov:100,100,100>']


@pytest.mark.parametrize('line', VALID)
def test_damaged_lines_never_raise_and_a_parsed_position_must_be_plausible(line) -> None:
    from growspace_gantry.position import bound_mm

    rng = random.Random(line)
    for variant in variants(line, rng):
        event = grbl.parse_line(variant)  # never raises
        if isinstance(event, grbl.Status):
            for name in ('mpos', 'wpos', 'wco'):
                value = getattr(event, name)
                assert value is None or len(value) == 3, (variant, event)
        s = Script(x=-275.0)
        before = dict(s.controller.position)
        s.feed(variant, dt=PERIOD_S)  # never raises
        after = s.controller.position
        if after is not None and after != before:
            jump = max(abs(after[a] - before[a]) for a in before)
            assert jump <= bound_mm(RIG[110], PERIOD_S), (variant, jump)
