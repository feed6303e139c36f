"""What to send next for one target and one lamp power: a jog's life as GRBL allows it.

Pure (no port, no clock): the controller tells it what GRBL answered and reported, and asks
it what to write. The rules, from GRBL 1.1's Jogging and Commands documentation:

- One jog at a time, to machine coordinates, sent only from Idle with no line in flight.
- A newer target (or none: a stop) cancels the jog with ``0x85`` only once GRBL has accepted
  the jog (its ``ok``) and reports Jog: GRBL ignores a jog cancel in any other state, so a
  cancel written before that is lost and the old jog runs to its end. After the cancel the
  newest target goes once GRBL reports Idle (a jog sent during the cancel would be flushed).
- A target gets one jog. A jog that ends short of its target without our cancel (a hold or a
  door on the machine) is a fault, never retried.
- G-code (the lamp's ``M3``/``M5``, the photo light's ``M8``/``M9``) only from Idle with no
  jog: GRBL refuses it while jogging (error:9). Both lights' lines go before the jog, so the
  photo light is off before the lamp moves.
- The driver only ever jogs, so any other motion state is a motion nobody commanded (GRBL
  restarts a jog as a cycle, ``Run``, when its segment buffer starves: protocol.c's auto cycle
  start) and is stopped by GRBL's own rules, since a jog cancel does nothing outside Jog: a
  feed hold ``!`` in ``Run``, nothing while a hold decelerates (``Hold:1``), and once stopped
  (``Hold:0``) a soft reset ``0x18``, which flushes the planner (the rest of the move) and
  switches the spindle (lamp) and coolant off; at ``Hold:0`` GRBL keeps its position and raises
  no alarm (motion_control.c, ``mc_reset``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from growspace_gantry import grbl
from growspace_gantry.calibration import Calibration

SETTLED_REPORTS = 2  # Idle reports in a row at one position: the machine stands there
SENT, ACCEPTED, RUNNING, CANCELLING = 'sent', 'accepted', 'running', 'cancelling'


@dataclass
class Jog:
    """The one jog on the machine."""

    target: dict[str, float]
    phase: str = SENT


class Motion:
    """The target, the lamp power asked for, and the jog on the machine.

    Args:
        cal: the calibration (feed rate, position tolerance).
    """

    def __init__(self, cal: Calibration, photo_light: bool = False) -> None:
        self.cal = cal
        self.target: dict[str, float] | None = None
        self.lamp_s = 0.0  # lamp power asked for [S]
        self.lamp_accepted: float | None = None  # lamp power of the last line GRBL accepted
        self.photo_managed = photo_light  # a photo light is wired to the flood coolant output
        self.photo = False  # photo light asked for
        self.photo_accepted: bool | None = None  # of the last M8/M9 GRBL accepted
        self.jog: Jog | None = None
        self.jogged = False  # the target's one jog was sent (or was not needed)
        self.queue: list[str] = []  # G-code waiting for Idle
        self.ask_status = False  # ask GRBL for a report now, not at the next period
        self.halting = False  # stopping a motion the driver did not start (Run, Hold)
        self._halt_byte: bytes | None = None  # the feed hold or soft reset due now

    @property
    def busy(self) -> bool:
        """A move is under way: a jog on the machine, one about to be sent, or an uncommanded
        motion being stopped."""
        return self.jog is not None or (self.target is not None and not self.jogged) \
            or self.halting

    def goto(self, target: Mapping[str, float]) -> None:
        self.target = dict(target)
        self.jogged = False

    def stop(self) -> None:
        """No target, lamp and photo light off (a running jog is cancelled at the next
        chance)."""
        self.target = None
        self.lamp_s = 0.0
        self.photo = False

    def forget(self) -> None:
        """The controller's buffers were emptied (a reset, a lost link): nothing is on it."""
        self.jog = None
        self.queue.clear()
        self.halting = False
        self._halt_byte = None
        self.lamp_accepted = None
        self.photo_accepted = None

    @property
    def lights_off(self) -> bool:
        """GRBL accepted the lines that switch the lamp (and the photo light) off."""
        return self.lamp_accepted == 0.0 and (not self.photo_managed
                                              or self.photo_accepted is False)

    def at(self, target: Mapping[str, float], position: Mapping[str, float] | None) -> bool:
        return position is not None and all(
            abs(position[a] - v) <= self.cal.position_tolerance_mm for a, v in target.items())

    def answered(self, line: str, ok: bool) -> None:
        """GRBL answered ``line`` (ours) with ``ok`` or an error (a jog refused is over)."""
        if line.startswith('$J='):
            if not ok:
                self.jog = None
            elif self.jog is not None and self.jog.phase == SENT:
                self.jog.phase = ACCEPTED
                self.ask_status = True
        elif ok and line in (grbl.PHOTO_ON, grbl.PHOTO_OFF):
            self.photo_accepted = line == grbl.PHOTO_ON
        elif ok and line.startswith('M'):
            self.lamp_accepted = 0.0 if line == 'M5' else float(line.split('S')[1])

    def reported(self, state: str, position: Mapping[str, float] | None,
                 settled: int, substate: int | None = None) -> str | None:
        """A believed report: where the jog is in its life. Returns a fault, or None."""
        if state in ('Run', 'Hold'):
            return self._uncommanded(state, substate)
        jog = self.jog
        if jog is None or jog.phase == SENT:
            return None  # before its ok, a report says nothing about the jog
        if state == 'Jog':
            if jog.phase == ACCEPTED:
                jog.phase = RUNNING
        elif state == 'Idle':
            if jog.phase == CANCELLING:
                self.jog = None  # cancelled: the newest target goes next
            elif settled < SETTLED_REPORTS:
                self.ask_status = True  # a second report at once, to confirm where it stopped
            else:
                self.jog = None
                if not self.at(jog.target, position):
                    return (f'the jog to {mm(jog.target)} stopped at {mm(position)} without a '
                            f'cancel of ours (a hold or a door on the machine?); not retried')
        elif state != 'Alarm':  # an alarm is reported by its own line
            self.jog = None
            return f'the controller went {state} during a jog'
        return None

    def _uncommanded(self, state: str, substate: int | None) -> str | None:
        """``Run`` or ``Hold``: a motion we did not start. Feed hold, then soft reset once
        stopped (``Hold:0``); the first report of it is a fault (the jog it came from, if any,
        is over)."""
        if state == 'Run':
            self._halt_byte = grbl.FEED_HOLD  # again at each Run report: idempotent in GRBL
        elif substate == 0:
            self._halt_byte = grbl.SOFT_RESET  # stopped: the reset flushes the rest, no alarm
        if self.halting:
            return None
        self.halting = True
        jog, self.jog = self.jog, None
        what = f'{state}:{substate}' if substate is not None else state
        during = f' during the jog to {mm(jog.target)}' if jog is not None else ''
        return (f'the controller went {what}{during}, a motion the driver did not start (GRBL '
                f'restarts a jog as a cycle when its segment buffer starves); a jog cancel does '
                f'nothing outside Jog: feed hold, then a soft reset once stopped')

    def due(self, state: str, position: Mapping[str, float] | None, settled: int,
            in_flight: int) -> bytes | str | None:
        """What to write now: ``0x85``, ``!`` or ``0x18`` (bytes), a line (str), or None."""
        if self._halt_byte is not None:
            halt, self._halt_byte = self._halt_byte, None
            return halt
        if self.halting:
            return None  # a hold decelerating: nothing else until the reset
        jog = self.jog
        if jog is not None:
            if jog.target != self.target and jog.phase == RUNNING and state == 'Jog':
                jog.phase = CANCELLING
                return grbl.JOG_CANCEL
            return None
        if state != 'Idle' or in_flight:
            return None  # one line in flight at a time
        if self.lamp_accepted != self.lamp_s and not self.queue:
            self.queue.append(grbl.lamp_line(self.lamp_s))
        if self.photo_managed and self.photo_accepted != self.photo and not self.queue:
            self.queue.append(grbl.PHOTO_ON if self.photo else grbl.PHOTO_OFF)
        if self.queue:
            return self.queue.pop(0)
        if self.target is None or self.jogged:
            return None
        self.jogged = True
        if settled >= SETTLED_REPORTS and self.at(self.target, position):
            return None  # already there
        self.jog = Jog(dict(self.target))
        return grbl.jog_line(self.target, self.cal.feed_mm_min)


def mm(position: Mapping[str, float] | None) -> str:
    """A machine position for a person: ``X -420.000, Z -300.000 mm``."""
    if position is None:
        return 'an unknown position'
    return ', '.join(f'{axis} {value:.3f}' for axis, value in sorted(position.items())) + ' mm'
