"""One GRBL 1.1 controller behind a link: connection, streaming, moves, lamp, faults.

Synchronous and polled: ``poll(now)`` reads what arrived, answers it and sends what is due; the
node calls it from a timer. The rules a machine builder expects, all here:

- Nothing is sent before the start-up banner; the ``$$`` settings are read at every connection
  and checked against the calibration (a contradiction is a fault: nothing moves).
- Lines are streamed by character counting against the 128-byte receive buffer.
- A move is a jog (``$J=``) to machine coordinates; a newer target cancels the running jog
  (0x85) and is sent once the machine is Idle, so the lamp follows the newest command, never a
  queue of stale ones. G-code (the lamp's ``M3``/``M5``) is only sent while Idle: GRBL refuses
  it during a jog (error:9).
- Lamp off is the safe state: ``safe_stop`` (hold + lamp off) for the watchdog, ``estop`` (feed
  hold, then soft reset, which also switches the spindle output off) for a person.
- An alarm is never unlocked here: only ``unlock`` (a person's request) sends ``$X``.
- A lost link closes the port; reconnection retries with a growing back-off.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from growspace_gantry import grbl
from growspace_gantry.calibration import Calibration
from growspace_gantry.link import Link, LinkLost

BANNER_TIMEOUT_S = 3.0  # after a soft reset GRBL prints its banner within ~1 s
SETTINGS_TIMEOUT_S = 3.0
BACKOFF_S = (0.5, 1.0, 2.0, 5.0, 10.0)  # reconnection delays, the last one repeats

OFFLINE, BOOTING, CONFIGURING, READY, FAULT = 'offline', 'booting', 'configuring', 'ready', \
    'fault'


@dataclass
class Log:
    """Where the controller's lines go (the node's throttled logger)."""

    warn: Callable[[str, str], object]  # (throttle key, text)
    info: Callable[[str], object]


class GrblController:
    """Drive one GRBL controller.

    Args:
        open_link: opens the link (raises LinkLost), called at start and on reconnection.
        calibration: the rig's calibration (checked against ``$$``).
        log: where warnings and information go.
        status_period_s: how often to ask for a status report (``?``).
    """

    def __init__(self, open_link: Callable[[], Link], calibration: Calibration, log: Log,
                 status_period_s: float = 0.1) -> None:
        self.open_link = open_link
        self.cal = calibration
        self.log = log
        self.status_period_s = status_period_s
        self.phase = OFFLINE
        self.link: Link | None = None
        self.counter = grbl.CharacterCounter()
        self.settings: dict[int, float] = {}
        self.status: grbl.Status | None = None
        self.position: dict[str, float] | None = None  # last reported machine position [mm]
        self.alarm: int | None = None  # active alarm code
        self.fault: str | None = None  # why nothing moves (settings mismatch), until restart
        self.failure: str | None = None  # the last refused line or lost move, for the node
        self.version = ''
        self.target: dict[str, float] | None = None  # where the machine should go / be
        self.lamp_s = 0.0  # lamp power the node wants [S]
        self._lamp_sent: float | None = None  # last lamp power the controller accepted a line for
        self._jog_sent = False  # the current target's jog line is on its way or running
        self._cancel_sent = False
        self._queue: list[str] = []  # G-code lines waiting for Idle
        self._deadline = 0.0
        self._next_status = 0.0
        self._retry_at = 0.0
        self._failures = 0
        self._last_wco: tuple[float, ...] | None = None
        self._now = 0.0  # time of the current poll [s]

    # --- state the node reads --------------------------------------------------------------

    @property
    def state(self) -> str:
        """The machine state of the last report ('Idle', 'Jog', 'Alarm', ...) or the phase."""
        if self.phase != READY:
            return self.phase
        return self.status.state if self.status else 'unknown'

    @property
    def ready(self) -> bool:
        """Connected, configured, not in alarm: moves are accepted."""
        return self.phase == READY and self.alarm is None

    def reached(self) -> bool:
        """The machine is Idle at the current target, with nothing left in flight."""
        if not self.ready or self.target is None or self.position is None:
            return False
        if self._jog_sent or self._queue or self.counter.pending or self.status.state != 'Idle':
            return False
        return all(abs(self.position[a] - v) <= self.cal.position_tolerance_mm
                   for a, v in self.target.items())

    def lamp_confirmed_off(self) -> bool:
        """Idle, and the controller accepted the lamp-off line (nothing left in flight)."""
        return (self.ready and self._lamp_sent == 0.0 and not self._queue
                and not self.counter.pending and self.status is not None
                and self.status.state == 'Idle')

    # --- requests --------------------------------------------------------------------------

    def goto(self, target: Mapping[str, float]) -> None:
        """Move to ``target`` (axis letter -> machine mm, already checked against the travel).

        A running jog to an older target is cancelled first.
        """
        self.target = dict(target)
        self.failure = None
        if self._jog_sent:
            self._cancel_jog()
        self._jog_sent = False

    def set_lamp(self, power_s: float) -> None:
        """Lamp power in S units (0 = off); sent at the next Idle, where GRBL accepts G-code."""
        self.lamp_s = power_s

    def safe_stop(self) -> None:
        """Hold and lamp off (watchdog, shutdown): cancel the jog, then M5 once Idle."""
        self.target = None
        self.lamp_s = 0.0
        if self.link is None:
            return
        if self._jog_sent or (self.status and self.status.state == 'Jog'):
            self._cancel_jog()
        elif self.status and self.status.state == 'Run':
            self._write(grbl.FEED_HOLD)
        self._jog_sent = False

    def estop(self) -> None:
        """Feed hold, then soft reset: motion stops and the spindle (lamp) output goes off.

        A reset during motion makes GRBL raise ALARM:3, which only a person clears (``unlock``).
        """
        self.target = None
        self.lamp_s = 0.0
        self._jog_sent = False
        if self.link is None:
            return
        if self._write(grbl.FEED_HOLD) and self._write(grbl.SOFT_RESET):
            self._after_reset(self._now)

    def unlock(self) -> str:
        """A person's ``$X``: leave the alarm state (the position may be wrong: re-home)."""
        if self.phase != READY:
            return f'not connected ({self.phase})'
        if self.alarm is None and (self.status is None or self.status.state != 'Alarm'):
            return 'not in alarm: nothing to unlock'
        self._send_line('$X')
        return ''

    def home(self) -> str:
        """A person's ``$H``, only if the controller has homing enabled ($22=1)."""
        if self.phase != READY:
            return f'not connected ({self.phase})'
        if self.settings.get(22) != 1.0:
            return f'homing is disabled on the controller ($22 = {self.settings.get(22)})'
        self._send_line('$H')
        return ''

    def close(self) -> None:
        """Close the link (the node turned the lamp off first)."""
        if self.link is not None:
            self.link.close()
        self.link = None
        self.phase = OFFLINE

    # --- the poll loop ---------------------------------------------------------------------

    def poll(self, now: float) -> None:
        """Read, answer and send what is due; reconnect when it is time."""
        self._now = now
        if self.link is None:
            if self.phase != FAULT and now >= self._retry_at:
                self._connect(now)
            return
        try:
            lines = self.link.read_lines()
        except LinkLost as e:
            self._lost(str(e), now)
            return
        for line in lines:
            self._handle(grbl.parse_line(line), line, now)
            if self.link is None:
                return
        if self.phase in (BOOTING, CONFIGURING) and now > self._deadline:
            self._lost(f'no answer from the controller within {BANNER_TIMEOUT_S:g} s '
                       f'({"banner" if self.phase == BOOTING else "$$ settings"})', now)
            return
        if self.phase == READY:
            if now >= self._next_status:
                self._next_status = now + self.status_period_s
                self._write(grbl.STATUS)
            self._send_due()

    def _connect(self, now: float) -> None:
        try:
            self.link = self.open_link()
        except LinkLost as e:
            self._schedule_retry(str(e), now)
            return
        self.log.info('gantry: link open; soft reset, waiting for the GRBL banner')
        if self._write(grbl.SOFT_RESET):  # a known state: stopped, lamp off, buffers empty
            self._after_reset(now)

    def _after_reset(self, now: float) -> None:
        self.counter.clear()
        self._queue.clear()
        self._lamp_sent = None
        self._jog_sent = self._cancel_sent = False
        self.status = None
        self.phase = BOOTING
        self._deadline = now + BANNER_TIMEOUT_S

    def _handle(self, event: grbl.Event, line: str, now: float) -> None:
        if isinstance(event, grbl.Banner):
            # After our reset or the controller's own (power glitch, reset button): whatever
            # was in flight is gone, the spindle output is off.
            self.version = event.version
            self._after_reset(now)
            self.settings = {}
            self.phase = CONFIGURING
            self._deadline = now + SETTINGS_TIMEOUT_S
            self._send_line('$$')
        elif isinstance(event, grbl.Setting):
            self.settings[event.number] = event.value
        elif isinstance(event, (grbl.Ok, grbl.Error)):
            sent = self.counter.acknowledged()
            if isinstance(event, grbl.Error):
                self.failure = f'{sent!r} refused: error:{event.code} ({event.meaning})'
                self.log.warn(f'grbl:error:{event.code}', f'gantry: {self.failure}')
                if sent is not None and sent.startswith('$J='):
                    self._jog_sent = False
                    self.target = None  # never retried: the node answers the step with this
            if self.phase == CONFIGURING and sent == '$$':
                self._configured(now)
        elif isinstance(event, grbl.Status):
            self._on_status(event)
        elif isinstance(event, grbl.Alarm):
            self.alarm = event.code
            self._jog_sent = False
            self._queue.clear()
            self.failure = f'ALARM:{event.code} ({event.meaning})'
            self.log.warn('grbl:alarm', f'gantry: {self.failure}. The driver never unlocks an '
                          f'alarm: check the machine, then call the gantry/unlock service '
                          f'(or gantry/home).')
        elif isinstance(event, grbl.Message):
            self.log.info(f'gantry: controller says: {event.text}')
            if event.text.startswith('Caution: Unlocked'):
                self.alarm = None
        elif isinstance(event, grbl.Unknown) and event.text:
            self.log.warn('grbl:unknown', f'gantry: ignored an unexpected line {line!r}')

    def _configured(self, now: float) -> None:
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
        self._next_status = now
        self.log.info(f'gantry: GRBL {self.version} ready ({len(self.settings)} settings '
                      f'checked against the calibration)')
        self._queue.append('M5')  # whatever the controller did before, the lamp starts off
        self._lamp_sent = 0.0

    def _on_status(self, status: grbl.Status) -> None:
        self.status = status
        if status.wco is not None:
            self._last_wco = status.wco
        position = status.machine_position(self._last_wco)
        if position is not None:
            self.position = dict(zip(grbl.AXES, position))
        if status.state == 'Alarm' and self.alarm is None:
            self.alarm = 0  # in alarm without a code (e.g. after power-up with homing enabled)
            self.failure = 'the controller is in the Alarm state'
            self.log.warn('grbl:alarm', 'gantry: the controller is in the Alarm state; the '
                          'driver never unlocks it: check the machine, then call gantry/unlock '
                          '(or gantry/home).')
        elif status.state != 'Alarm' and self.alarm is not None:
            self.alarm = None
        if status.state == 'Idle':
            self._cancel_sent = False
            if self._jog_sent and not self.counter.pending:
                self._jog_sent = False  # the jog is over (reached, or cut short by a cancel)

    def _send_due(self) -> None:
        """Send queued G-code and the current target's jog when the machine allows it."""
        if self.alarm is not None or self.status is None or self._cancel_sent:
            return
        idle = self.status.state == 'Idle' and not self._jog_sent
        if idle and self._lamp_sent != self.lamp_s:
            self._queue.append(grbl.lamp_line(self.lamp_s))
            self._lamp_sent = self.lamp_s
        while self._queue and idle and self.counter.fits(self._queue[0]):
            self._send_line(self._queue.pop(0))
        if self.target is not None and not self._jog_sent and not self._queue \
                and self.status.state in ('Idle', 'Jog') and not self._at_target():
            line = grbl.jog_line(self.target, self.cal.feed_mm_min)
            if self.counter.fits(line):
                self._send_line(line)
                self._jog_sent = True

    def _at_target(self) -> bool:
        return self.position is not None and all(
            abs(self.position[a] - v) <= self.cal.position_tolerance_mm
            for a, v in self.target.items())

    def _cancel_jog(self) -> None:
        if not self._cancel_sent and self.link is not None:
            self._write(grbl.JOG_CANCEL)
            self._cancel_sent = True

    def _send_line(self, line: str) -> None:
        if self._write(line.encode('ascii') + b'\n'):
            self.counter.sent(line)

    def _write(self, data: bytes) -> bool:
        """Write to the link; a failure closes it (``link`` becomes None) and returns False."""
        if self.link is None:
            return False
        try:
            self.link.write(data)
        except LinkLost as e:
            self._lost(str(e), self._now)
            return False
        return True

    def _lost(self, reason: str, now: float) -> None:
        if self.link is not None:
            self.link.close()
        self.link = None
        self.phase = OFFLINE
        self.status = None
        self.position = None
        self._jog_sent = False
        self.failure = f'link lost: {reason}'
        self._schedule_retry(reason, now)

    def _schedule_retry(self, reason: str, now: float) -> None:
        delay = BACKOFF_S[min(self._failures, len(BACKOFF_S) - 1)]
        self._failures += 1
        self._retry_at = now + delay
        self.log.warn('link', f'gantry: link down ({reason}); the lamp state is unknown until '
                      f'the controller answers again (a reconnection resets it, lamp off); '
                      f'retrying in {delay:g} s')
