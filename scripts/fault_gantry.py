"""Fault injection on the gantry driver against the GRBL emulator: what was injected, how often,
and what held. Prints the README's gantry fault table.

Method (fixed): gantry_node's logic (``GantryNode`` over the in-process transport) drives the
pty GRBL emulator of the tests (moves ``SPEEDUP`` times faster than real time; jog cancels and
holds decelerate at the emulator's $120). Each scenario is repeated ``--repeats`` times with
seeds 0.. (targets drawn from the seed); a scenario "holds" when every check listed for it held
in every repeat. Checks are read from the emulator's side (the lines and real-time bytes it
received, its jogs, spindle and position), not from the driver's own state.

    PYTHONPATH=tests python scripts/fault_gantry.py      # inside the sourced workspace
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
import sys
import tempfile
import time
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'tests'))

from grbl_emulator import GrblEmulator, random_damage  # noqa: E402
from growspace_gantry import calibration  # noqa: E402
from growspace_gantry.controller import GrblController, Log  # noqa: E402
from growspace_gantry.link import SerialLink  # noqa: E402
from growspace_gantry.main import default_calibration  # noqa: E402
from growspace_gantry.node import GantryNode  # noqa: E402
from growspace_gantry.settings import GantryParams  # noqa: E402
from growspace_sim.core.config import SimConfig  # noqa: E402
from growspace_sim.node.fake import FakeTransport  # noqa: E402
from growspace_sim.ros import convert, types  # noqa: E402

RIG = {10: 1, 20: 1, 22: 0, 30: 1000, 32: 1, 110: 6000, 111: 6000, 112: 6000, 130: 900,
       131: 900, 132: 500}
SPEEDUP = 40.0
X0 = -845.0  # machine X of chamber x = 0 (shipped calibration)
MOVES = ('$J', 'M3')


class Harness:
    """One emulated controller and one gantry node, polled at 500 Hz."""

    def __init__(self, tmp: str, mode: str = 'lockstep', emulator: dict | None = None,
                 **params: Any) -> None:
        self.grbl = GrblEmulator(RIG, link_dir=tmp, **{'speedup': SPEEDUP, **(emulator or {})})
        self.grbl.start()
        self.t = FakeTransport('growspace_gantry')
        self.c = GrblController(lambda: SerialLink(self.grbl.port),
                                calibration.load(default_calibration()),
                                Log(self.t.logger.warn, self.t.logger.info), 0.02)
        self.node = GantryNode(self.t, self.c, SimConfig(), GantryParams(
            port=self.grbl.port, mode=mode, seed=1, **{'watchdog_s': 60.0, **params}))
        self.errors: list[str] = []

    def until(self, done: Callable[[], bool], timeout: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                self.node.poll()
            except Exception as e:  # noqa: BLE001 - counted: a poll must never raise
                self.errors.append(repr(e))
            if done():
                return True
            time.sleep(0.002)
        return False

    def results(self) -> list[Any]:
        return self.t.messages('step_result')

    def send(self, step_id: int = 0, **fields: Any) -> None:
        self.t.inject('light/command', types.new(types.LIGHT_COMMAND, step_id=step_id,
                                                 **fields))

    def place(self, seed: int) -> bool:
        n = len(self.results())
        self.t.inject('reset', types.new(types.RESET_REQUEST, reset_id=seed + 1, has_seed=True,
                                         seed=seed))
        return self.until(lambda: len(self.results()) > n) and self.results()[-1].info == ''

    def moves_after(self, mark: int) -> list[str]:
        return [line for line in self.grbl.lines[mark:] if line.startswith(MOVES)]

    def close(self) -> None:
        self.node.close()
        self.grbl.stop()


def far(rng: np.random.Generator) -> float:
    return float(rng.choice([rng.uniform(0.1, 0.25), rng.uniform(0.6, 0.75)]))


def lost_link(h: Harness, rng: np.random.Generator) -> bool:
    h.place(int(rng.integers(100)))
    h.send(1, mode=convert.MODE_BEAM, x=far(rng), width=0.2)
    h.until(lambda: h.grbl.state == 'Jog')
    h.grbl.unplug()
    h.until(lambda: h.c.phase == 'offline')
    answered = 'link lost' in h.results()[-1].info
    mark = len(h.grbl.lines)
    h.grbl.replug()
    h.until(lambda: h.c.ready)
    h.until(lambda: False, 0.5)
    return answered and not h.moves_after(mark) and h.grbl.spindle[0] == 'M5'


def restart(h: Harness, rng: np.random.Generator) -> bool:
    h.place(int(rng.integers(100)))
    h.send(1, mode=convert.MODE_BEAM, x=far(rng), width=0.2)
    h.until(lambda: h.grbl.state == 'Jog')
    mark = len(h.grbl.lines)
    h.grbl.restart()
    h.until(lambda: h.grbl.lines.count('$$') == 2 and h.c.ready)
    h.until(lambda: False, 0.5)
    h.send(2, mode=convert.MODE_DISCRETE, action=1)  # relative: refused until re-placed
    h.until(lambda: h.results()[-1].step_id == 2)
    refused = 're-established' in h.results()[-1].info
    return refused and not h.moves_after(mark) and h.grbl.spindle[0] == 'M5'


def alarm_then_unlock(h: Harness, rng: np.random.Generator) -> bool:
    h.place(int(rng.integers(100)))
    h.send(1, mode=convert.MODE_BEAM, x=far(rng), width=0.2)
    h.until(lambda: h.grbl.state == 'Jog')
    h.grbl.trigger_alarm(int(rng.choice([1, 2])))
    h.until(lambda: h.c.alarm is not None)
    mark = len(h.grbl.lines)
    h.t.services['gantry/unlock'](types.new('std_srvs/srv/Trigger_Request'))
    h.until(lambda: h.grbl.state == 'Idle')
    h.until(lambda: False, 0.5)
    return not h.moves_after(mark) and h.grbl.spindle[0] == 'M5'


def estop(moving: bool) -> Callable[[Harness, np.random.Generator], bool]:
    def run(h: Harness, rng: np.random.Generator) -> bool:
        h.place(int(rng.integers(100)))
        if moving:
            h.send(1, mode=convert.MODE_BEAM, x=far(rng), width=0.2)
            h.until(lambda: h.grbl.state == 'Jog')
        h.t.services['gantry/estop'](types.new('std_srvs/srv/Trigger_Request'))
        h.until(lambda: h.grbl.lines.count('$$') == 2 and h.c.status is not None)
        mark = len(h.grbl.lines)
        h.send(2, mode=convert.MODE_BEAM, x=0.5, width=0.2)
        h.until(lambda: h.results()[-1].step_id == 2)
        h.until(lambda: False, 0.3)
        return h.results()[-1].info.startswith('error') and not h.moves_after(mark) \
            and h.grbl.spindle[0] == 'M5'
    return run


def flood(h: Harness, rng: np.random.Generator) -> bool:
    """200 commands in 2 s; holds: ends on the newest, lit, every cancel acted on, no
    superseded jog ran on for more than 0.25 s after it was superseded."""
    h.place(int(rng.integers(100)))
    h.grbl.speedup = 10.0
    xs = [round(far(rng), 4) for _ in range(200)]
    sent = []
    for x in xs:
        h.send(mode=convert.MODE_BEAM, x=x, width=0.2)
        sent.append(time.monotonic())
        h.until(lambda: False, 0.01)
    h.until(lambda: h.c.reached(), 20.0)
    index = {round(X0 + 1000.0 * x, 1): i for i, x in enumerate(xs)}
    overrun = [jog['end'] - sent[i + 1] for jog in h.grbl.jogs[:-1]
               if jog['outcome'] == 'done' and (i := index.get(round(jog['target'][0], 1)))
               is not None and i + 1 < len(sent)]
    Stats.flood_cancels += len(h.grbl.cancels)
    Stats.flood_late += h.grbl.cancels.count('late')
    Stats.flood_overrun = max([Stats.flood_overrun, *overrun])
    return (abs(h.grbl.mpos[0] - (X0 + 1000.0 * xs[-1])) <= 0.05
            and h.grbl.spindle == ('M3', 1000.0)
            and not {'early', 'ignored', 'repeat'} & set(h.grbl.cancels)
            and all(t < 0.25 for t in overrun))


def damaged(h: Harness, rng: np.random.Generator) -> bool:
    """An episode of 30 discrete steps with every 5th status line damaged (a byte flipped,
    dropped or inserted); holds: no exception, every step answered at the reported light,
    one jog per moving step."""
    h.grbl.damage = random_damage(5, seed=int(rng.integers(1 << 30)))
    h.place(int(rng.integers(100)))
    moved = 0
    for step_id in range(1, 31):
        before = h.t.messages('light/state')[-1]
        n = len(h.results())
        h.send(step_id, mode=convert.MODE_DISCRETE, action=int(rng.integers(5)))
        if not h.until(lambda n=n: len(h.results()) > n) or h.results()[-1].info:
            return False
        after = h.t.messages('light/state')[-1]
        moved += abs(after.x - before.x) > 1e-4 or abs(after.width - before.width) > 1e-4
    Stats.damaged_lines += len(h.grbl.damaged)
    jogs = sum(1 for line in h.grbl.lines if line.startswith('$J'))
    return not h.errors and jogs == moved + 1


def refused_jog(h: Harness, rng: np.random.Generator) -> bool:
    h.place(int(rng.integers(100)))
    x0 = h.grbl.mpos[0]
    h.grbl.reject_next.append(15)
    h.send(1, mode=convert.MODE_DISCRETE, action=int(rng.choice([0, 1])))
    h.until(lambda: h.results()[-1].step_id == 1)
    mark = len(h.grbl.lines)
    h.send(2, mode=convert.MODE_DISCRETE, action=2)  # stay
    h.until(lambda: h.results()[-1].step_id == 2)
    return 'error:15' in h.results()[-2].info and h.results()[-1].info == '' \
        and not [x for x in h.moves_after(mark) if x.startswith('$J')] and h.grbl.mpos[0] == x0


def cycle_from_jog(hold_button: bool) -> Callable[[Harness, np.random.Generator], bool]:
    """GRBL restarts the jog as a cycle (a starved segment buffer: Run), with or without a hold
    button pressed then (Hold); holds: the step failed saying so, the rest of the move never
    ran (the emulator's jog ends 'reset'), Idle with the lamp off, no alarm, nothing sent after."""
    def run(h: Harness, rng: np.random.Generator) -> bool:
        h.place(int(rng.integers(100)))
        h.grbl.speedup = 10.0  # a move of seconds: the cycle begins mid-move
        h.send(1, mode=convert.MODE_BEAM, x=far(rng), width=0.2)
        h.until(lambda: h.grbl.state == 'Jog')
        mark, began = len(h.grbl.lines), h.grbl.mpos
        if not h.grbl.starve_segment_buffer():
            return False
        if hold_button:
            h.grbl.press_feed_hold()
        h.until(lambda: h.grbl.state == 'Idle' and h.grbl.spindle[0] == 'M5' and h.c.ready)
        h.until(lambda: False, 0.3)
        Stats.cycle_overrun = max(Stats.cycle_overrun, abs(h.grbl.mpos[0] - began[0]))
        return (h.grbl.jogs[-1]['outcome'] == 'reset' and h.grbl.state == 'Idle'
                and h.grbl.spindle[0] == 'M5' and 'went' in h.results()[-1].info
                and not h.moves_after(mark) and h.c.alarm is None)
    return run


class Stats:
    flood_cancels = flood_late = damaged_lines = 0
    flood_overrun = cycle_overrun = 0.0


SCENARIOS = [
    ('link lost mid-move (unplug), then replugged', lost_link, {}, 'step failed at once; after '
     'reconnection no jog and no M3 until a new command'),
    ('controller restart mid-move (banner, MPos 0)', restart, {}, 'no jog, no M3; a relative '
     'action refused until a reset'),
    ('ALARM:1/2 mid-move, then gantry/unlock', alarm_then_unlock, {}, 'unlock sent $X only: '
     'nothing moved, lamp off'),
    ('e-stop mid-move, GRBL answers ALARM:3', estop(True), {}, 'latched: next command refused, '
     'nothing moved'),
    ('e-stop mid-move, GRBL comes back Idle (no alarm)', estop(True), {'reset_alarm': False},
     'latched: next command refused, nothing moved'),
    ('e-stop while idle (GRBL never alarms)', estop(False), {}, 'latched: next command '
     'refused, nothing moved'),
    ('200 commands in 2 s (realtime)', flood, {'mode': 'realtime'}, 'ended on the newest, lit; '
     'no cancel ignored by GRBL'),
    ('every 5th status line damaged, 30 steps', damaged, {}, 'no exception; every step answered; '
     'one jog per moving step'),
    ('jog refused (error:15), then "stay"', refused_jog, {}, 'no jog: the light stayed where '
     'the machine was'),
    ('GRBL restarts a jog as a cycle (Run, a starved segment buffer)', cycle_from_jog(False),
     {}, 'feed hold, soft reset at Hold:0: the rest of the move never ran, lamp off, no alarm'),
    ('a jog restarted as a cycle, then a hold button (Hold)', cycle_from_jog(True), {},
     'soft reset at Hold:0: the rest of the move never ran, lamp off, no alarm'),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--repeats', type=int, default=10)
    parser.add_argument('--only', default='', help='run the scenarios whose name holds this')
    args = parser.parse_args()
    rows = []
    for name, scenario, options, what in SCENARIOS:
        if args.only not in name:
            continue
        options = dict(options)
        mode = options.pop('mode', 'lockstep')
        held = 0
        for seed in range(args.repeats):
            with tempfile.TemporaryDirectory() as tmp:
                h = Harness(tmp, mode=mode, emulator=options)
                try:
                    h.until(lambda h=h: h.c.ready)
                    held += bool(scenario(h, np.random.default_rng(seed)))
                finally:
                    h.close()
        rows.append((name, args.repeats, f'{held}/{args.repeats}', what))
        print(f'{name}: held {held}/{args.repeats}', file=sys.stderr, flush=True)
    print('| fault injected | times | held | what held |')
    print('|---|---|---|---|')
    for name, times, held, what in rows:
        print(f'| {name} | {times} | {held} | {what} |')
    print(f'\nflood: {Stats.flood_cancels} jog cancels sent, {Stats.flood_late} crossed their '
          f"jog's end on the wire; longest run of a superseded jog after a newer command: "
          f'{Stats.flood_overrun:.3f} s. Damaged status lines: {Stats.damaged_lines}. A jog '
          f'restarted as a cycle ran on at most {Stats.cycle_overrun:.1f} mm.')


if __name__ == '__main__':
    main()
