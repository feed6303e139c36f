"""One GRBL 1.1 controller behind a link: connection, streaming, jogs, lamp, faults.

Synchronous and polled: ``poll(now)`` reads what arrived, answers it, sends what is due and
returns what went wrong (``Fault``) or was done (``Homed``) meanwhile; the node applies the
safety rules to those (``safety.py``). What this layer guarantees:

- Nothing is sent before the start-up banner; the ``$$`` settings are read at every connection
  and checked against the calibration (a contradiction is a fault: nothing moves).
- Character counting against the 128-byte receive buffer, one line in flight at a time.
- A move is one jog to machine coordinates, cancelled the way GRBL allows (``motion.py``).
- Every fault clears the target and the lamp power asked for: nothing moves or lights up again
  until the node asks anew.
- A position is believed only from a well-formed report (``grbl.parse_line``) that is
  plausible (``position.py``); the machine has reached a target when two Idle reports agree.
- An alarm is never unlocked here: only ``unlock`` and ``home`` (a person's requests) send
  ``$X`` and ``$H``. A lost link closes the port; reconnection retries with a growing back-off.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from growspace_gantry import grbl, position as positions
from growspace_gantry.calibration import Calibration
from growspace_gantry.link import Link, LinkLost
from growspace_gantry.motion import Motion, SETTLED_REPORTS

BANNER_TIMEOUT_S = 3.0  # after a soft reset GRBL prints its banner within ~1 s
SETTINGS_TIMEOUT_S = 3.0
SILENCE_S = 3.0  # connected, and nothing heard for this long (status asked at >= 0.5 Hz): lost
BACKOFF_S = (0.5, 1.0, 2.0, 5.0, 10.0)  # reconnection delays, the last one repeats

OFFLINE, BOOTING, CONFIGURING, READY, FAULT = 'offline', 'booting', 'configuring', 'ready', \
    'fault'


@dataclass
class Log:
    """Where the controller's lines go (the node's throttled logger)."""

    warn: Callable[[str, str], object]  # (throttle key, text)
    info: Callable[[str], object]


@dataclass(frozen=True)
class Fault:
    """Something stopped the machine or refused our move; the target is already cleared."""

    reason: str
    position_lost: bool = False  # the machine may not be where GRBL reports it


@dataclass(frozen=True)
class Homed:
    """A person's homing cycle ($H) finished: the machine position is known again."""


class GrblController:
    """Drive one GRBL controller.

    Args:
        open_link: opens the link (raises LinkLost), called at start and on reconnection.
        calibration: the rig's calibration (checked against ``$$``).
        log: where warnings and information go.
        status_period_s: how often to ask for a status report (``?``).
        photo_light: a white photo light is wired to the flood coolant output (``M8``/``M9``):
            it is switched off at every connection and on every fault, like the lamp.
    """

    def __init__(self, open_link: Callable[[], Link], calibration: Calibration, log: Log,
                 status_period_s: float = 0.1, photo_light: bool = False) -> None:
        self.open_link = open_link
        self.cal = calibration
        self.log = log
        self.status_period_s = status_period_s
        self.phase = OFFLINE
        self.link: Link | None = None
        self.counter = grbl.CharacterCounter()
        self.settings: dict[int, float] = {}
        self.status: grbl.Status | None = None  # the last believed report
        self.position: dict[str, float] | None = None  # believed machine position [mm]
        self.alarm: int | None = None  # active alarm code (0: in Alarm without a code)
        self.fault: str | None = None  # why nothing moves (settings mismatch), until restart
        self.failure: str | None = None  # the last failure, until the next recovery
        self.version = ''
        self.motion = Motion(calibration, photo_light)  # the target, the lights, the jog
        self._events: list[Fault | Homed] = []
        self._own_reset = False  # the next banner answers our own soft reset
        self._filter = positions.PositionFilter()
        self._settled = 0  # Idle reports in a row at the believed position
        self._deadline = self._next_status = self._retry_at = self._heard = 0.0
        self._failures = 0
        self._last_wco: tuple[float, ...] | None = None
        self._now = 0.0  # time of the current poll [s]

    # --- state the node reads --------------------------------------------------------------

    @property
    def state(self) -> str:
        """The machine state of the last report ('Idle', 'Jog', 'Alarm', ...) or the phase."""
        return self.phase if self.phase != READY else self.status.state if self.status \
            else 'unknown'

    @property
    def ready(self) -> bool:
        """Connected, configured, a report read, not in alarm: moves are accepted."""
        return self.phase == READY and self.alarm is None and self.status is not None

    @property
    def lamp_reported(self) -> float | None:
        """The lamp power (S) the controller reports (status FS); None when unknown."""
        return self.status.speed if self.phase == READY and self.status is not None else None

    @property
    def target(self) -> dict[str, float] | None:
        """Where the machine should go [mm]; None: stay."""
        return self.motion.target

    @property
    def lamp_s(self) -> float:
        """The lamp power asked for [S]."""
        return self.motion.lamp_s

    @property
    def busy(self) -> bool:
        """A move is under way: a jog on the machine, or one about to be sent."""
        return self.motion.busy

    def reached(self) -> bool:
        """Idle at the current target (two reports agree), nothing in flight."""
        m = self.motion
        return (self.ready and m.target is not None and m.jog is None and m.jogged
                and not m.queue and not self.counter.pending and self.status.state == 'Idle'
                and self._settled >= SETTLED_REPORTS and m.at(m.target, self.position))

    @property
    def has_photo_light(self) -> bool:
        """A photo light is wired to the flood coolant output (``photo_light``)."""
        return self.motion.photo_managed

    @property
    def photo_light_accepted(self) -> bool | None:
        """The photo light as the last ``M8``/``M9`` GRBL accepted left it (None: unknown)."""
        return self.motion.photo_accepted

    def photo_light_on(self) -> bool:
        """Idle at the target with the photo light on: GRBL accepted ``M8`` and nothing is
        queued or in flight."""
        return self.reached() and self.motion.photo and self.motion.photo_accepted is True

    def lamp_confirmed_off(self) -> bool:
        """Idle, and the controller accepted the lines that switch the lamp and the photo
        light off (nothing left in flight)."""
        return (self.ready and self.motion.lights_off and not self.motion.queue
                and not self.counter.pending and self.status.state == 'Idle')

    # --- requests --------------------------------------------------------------------------

    def goto(self, target: Mapping[str, float]) -> None:
        """Move to ``target`` (axis letter -> machine mm, checked against the travel); a jog to
        an older target is cancelled first (once GRBL allows it)."""
        self.motion.goto(target)
        self.failure = None

    def set_lamp(self, power_s: float) -> None:
        """Lamp power in S units (0 = off); sent at the next Idle, where GRBL accepts G-code."""
        self.motion.lamp_s = power_s

    def set_photo_light(self, on: bool) -> None:
        """The photo light (``M8``/``M9``), sent at the next Idle; ignored without one."""
        self.motion.photo = on and self.motion.photo_managed

    def safe_stop(self) -> None:
        """No target, lamp and photo light off: a running jog is cancelled, then ``M5`` (and
        ``M9``) once Idle."""
        self.motion.stop()

    def estop(self) -> bool:
        """Feed hold, then soft reset: motion stops, the spindle (lamp) output goes off.

        Returns:
            Whether the machine may have been moving (then its position may be lost).
        """
        moving = self.motion.jog is not None or self.status is None \
            or self.status.state != 'Idle'
        self.safe_stop()
        if self.link is not None and self._write(grbl.FEED_HOLD) \
                and self._write(grbl.SOFT_RESET):
            self._after_reset(self._now)
        return moving

    def unlock(self) -> str:
        """A person's ``$X``: leave the alarm state. Returns '' or why it was not sent."""
        if self.phase != READY:
            return f'not connected ({self.phase})'
        if self.alarm is None:
            return 'not in alarm: nothing to unlock'
        self.safe_stop()
        self._send_line('$X')
        return ''

    def home(self) -> str:
        """A person's ``$H``, only if the controller has homing enabled ($22=1)."""
        if self.phase != READY:
            return f'not connected ({self.phase})'
        if self.settings.get(22) != 1.0:
            return f'homing is disabled on the controller ($22 = {self.settings.get(22)})'
        if self.motion.jog is not None:
            return 'the machine is moving; stop it first'
        if self.counter.pending:
            return 'the controller has not answered the last line yet; try again'
        self.safe_stop()
        self._send_line('$H')
        return ''

    def close(self) -> None:
        """Close the link (the node turned the lamp off first)."""
        if self.link is not None:
            self.link.close()
        self.link = None
        self.phase = OFFLINE

    # --- the poll loop ---------------------------------------------------------------------

    def poll(self, now: float) -> list[Fault | Homed]:
        """Read, answer and send what is due; reconnect when it is time.

        Returns:
            The faults and finished homing cycles seen during this poll.
        """
        self._now = now
        self._events = []
        if self.link is None:
            if self.phase != FAULT and now >= self._retry_at:
                self._connect(now)
            return self._events
        try:
            lines = self.link.read_lines()
        except LinkLost as e:
            self._lost(str(e))
            return self._events
        for line in lines:
            self._heard = now
            self._handle(grbl.parse_line(line), line)
            if self.link is None:
                return self._events
        if self.phase in (BOOTING, CONFIGURING) and now > self._deadline:
            self._lost(f'no answer from the controller within {BANNER_TIMEOUT_S:g} s '
                       f'({"banner" if self.phase == BOOTING else "$$ settings"})')
        elif self.phase == READY and now - self._heard > SILENCE_S and '$H' not in \
                self.counter.in_flight:  # GRBL does not answer ? while homing
            self._lost(f'no answer from the controller for {SILENCE_S:g} s')
        elif self.phase == READY:
            if now >= self._next_status or self.motion.ask_status:
                self._next_status = now + self.status_period_s
                self.motion.ask_status = False
                self._write(grbl.STATUS)
            self._send_due()
        return self._events

    def _connect(self, now: float) -> None:
        try:
            self.link = self.open_link()
        except LinkLost as e:
            self._schedule_retry(str(e))
            return
        self.log.info('gantry: link open; soft reset, waiting for the GRBL banner')
        if self._write(grbl.SOFT_RESET):  # a known state: stopped, lamp off, buffers empty
            self._after_reset(now)

    def _after_reset(self, now: float) -> None:
        self.counter.clear()
        self.motion.forget()
        self.status = self.position = None
        self._filter.reset()
        self._settled = 0
        self._own_reset = True
        self.phase = BOOTING
        self._deadline = now + BANNER_TIMEOUT_S

    def _handle(self, event: grbl.Event, line: str) -> None:
        if isinstance(event, grbl.Banner):
            # After our reset, or the controller's own (power glitch, reset button): whatever
            # was in flight is gone, the spindle output is off, the position may be 0,0,0.
            if self.phase == READY and not self._own_reset:
                self._fail(f'the controller restarted (GRBL {event.version} banner, no reset '
                           f'of ours): its position is lost', position_lost=True)
            self.version = event.version
            self._after_reset(self._now)
            self._own_reset = False
            self.settings = {}
            self.phase = CONFIGURING
            self._deadline = self._now + SETTINGS_TIMEOUT_S
            self._send_line('$$')
        elif isinstance(event, grbl.Setting):
            self.settings[event.number] = event.value
        elif isinstance(event, (grbl.Ok, grbl.Error)):
            self._answer(event)
        elif isinstance(event, grbl.Status):
            self._on_status(event)
        elif isinstance(event, grbl.Alarm):
            self.alarm = event.code
            self.motion.forget()  # GRBL flushed its planner
            text = grbl.alarm_text(event.code)
            self._fail(text, position_lost=event.code in grbl.POSITION_LOST_ALARMS)
            self.log.warn('grbl:alarm', f'gantry: {text}. The driver never unlocks an alarm: '
                          f'check the machine, then call gantry/unlock (or gantry/home).')
        elif isinstance(event, grbl.Message):
            self.log.info(f'gantry: controller says: {event.text}')
        elif isinstance(event, grbl.Unknown) and event.text:
            self.log.warn('grbl:unknown', f'gantry: ignored a line that does not follow the '
                          f'protocol (damaged?): {line!r}')

    def _answer(self, event: grbl.Ok | grbl.Error) -> None:
        """An ``ok`` or ``error:N`` for the oldest line in flight."""
        sent = self.counter.acknowledged()
        if sent is None:
            return  # an answer to nothing of ours (e.g. a line sent before a reset)
        ok = isinstance(event, grbl.Ok)
        self.motion.answered(sent, ok)
        if not ok:
            text = f'{sent!r} refused: error:{event.code} ({event.meaning})'
            self.log.warn(f'grbl:error:{event.code}', f'gantry: {text}')
            if sent in ('$X', '$H', '$$'):
                self.failure = text  # a person's request, or the settings: nothing moved
            else:
                self._fail(text)  # a jog or the lamp: the move it belonged to is over
        elif sent == '$H':
            self.failure = None
            self._filter.reset()  # homing sets the machine position: no plausible path to it
            self._events.append(Homed())
        elif sent == '$X':
            self.failure = None
        if self.phase == CONFIGURING and sent == '$$':
            self._configured()

    def _configured(self) -> None:
        problems = self.cal.check_settings(self.settings)
        if problems:
            self.fault = '; '.join(problems)
            self.log.warn('grbl:settings', f"gantry: the controller's settings do not match "
                          f'the calibration, nothing will move: {self.fault}')
            self.link.close()
            self.link = None
            self.phase = FAULT
            return
        self.phase = READY
        self._failures = 0
        self.failure = None
        self._next_status = self._heard = self._now
        self.log.info(f'gantry: GRBL {self.version} ready ({len(self.settings)} settings '
                      f'checked against the calibration)')
        self.motion.queue.append('M5')  # whatever the controller did before, the lamp is off

    def _on_status(self, status: grbl.Status) -> None:
        if status.wco is not None:
            self._last_wco = status.wco
        reported = status.machine_position(self._last_wco)
        if reported is not None:
            place = dict(zip(grbl.AXES, reported))
            verdict = self._filter.offer(place, self._now, self._max_rate())
            if verdict == positions.REJECTED:
                self.log.warn('grbl:implausible', f'gantry: ignored a status report whose '
                              f'position is implausible (damaged?): {place} after '
                              f'{self.position}')
                return
            if verdict == positions.REANCHORED:
                self.log.warn('grbl:reanchored', f'gantry: the machine was moved to {place} '
                              f'by something else (three reports agree)')
            same = self.position == place
            self.position = place
        else:
            same = False
        self.status = status
        self._settled = (self._settled + 1 if same else 1) if status.state == 'Idle' else 0
        if status.state == 'Alarm' and self.alarm is None:
            self.alarm = 0  # in alarm without a code (e.g. after power-up with homing enabled)
            self.motion.forget()
            self._fail(grbl.alarm_text(None), position_lost=True)
            self.log.warn('grbl:alarm', f'gantry: {grbl.alarm_text(None)}; the driver never '
                          f'unlocks it: check the machine, then call gantry/unlock (or '
                          f'gantry/home).')
        elif status.state != 'Alarm' and self.alarm is not None:
            self.alarm = None  # left by $X or $H
        problem = self.motion.reported(status.state, self.position, self._settled,
                                       status.substate)
        if problem:  # halting: an uncommanded motion ran the light where nobody asked
            self._fail(problem, position_lost=self.motion.halting)
            if self.motion.halting:
                self.log.warn('grbl:uncommanded', f'gantry: {problem}; lamp off')

    def _send_due(self) -> None:
        """Write what the motion asks for (a jog cancel, a lamp line, the next jog)."""
        if self.alarm is not None or self.status is None:
            return
        due = self.motion.due(self.status.state, self.position, self._settled,
                              self.counter.pending)
        if isinstance(due, bytes):  # a soft reset: an uncommanded motion stopped, flush it
            if self._write(due) and due == grbl.SOFT_RESET:
                self._after_reset(self._now)
        elif due is not None:
            self._send_line(due)

    def _max_rate(self) -> float:
        """The fastest the machine can move [mm/min]: its max rates and homing seek rate."""
        return max([self.settings.get(n, 0.0) for n in (110, 111, 112, 25)]
                   + [self.cal.feed_mm_min])

    def _fail(self, reason: str, position_lost: bool = False) -> None:
        """A fault: the target and the lamp power asked for are cleared."""
        self.safe_stop()
        self.failure = reason
        self._events.append(Fault(reason, position_lost))

    def _send_line(self, line: str) -> None:
        if self.counter.fits(line) and self._write(line.encode('ascii') + b'\n'):
            self.counter.sent(line)

    def _write(self, data: bytes) -> bool:
        """Write to the link; a failure closes it (``link`` becomes None) and returns False."""
        if self.link is None:
            return False
        try:
            self.link.write(data)
        except LinkLost as e:
            self._lost(str(e))
            return False
        return True

    def _lost(self, reason: str) -> None:
        if self.link is not None:
            self.link.close()
        self.link = None
        self.phase = OFFLINE
        self.status = self.position = None
        self._filter.reset()
        self.motion.forget()
        self.counter.clear()
        self._fail(f'link lost: {reason}', position_lost=True)
        self._schedule_retry(reason)

    def _schedule_retry(self, reason: str) -> None:
        delay = BACKOFF_S[min(self._failures, len(BACKOFF_S) - 1)]
        self._failures += 1
        self._retry_at = self._now + delay
        self.log.warn('link', f'gantry: link down ({reason}); the lamp state is unknown until '
                      f'the controller answers again (a reconnection resets it, lamp off); '
                      f'retrying in {delay:g} s')

