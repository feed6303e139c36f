"""A GRBL 1.1 controller on a pseudo-terminal, for the gantry tests only (never shipped).

Written from GRBL 1.1's own documentation (the Interface, Commands, Jogging, Laser Mode and
Configuration pages, its error and alarm tables) and from what a real GRBL 1.1h printed
(shared/design/gantry.md), not from the driver: a shared mistake would otherwise pass.
What it models:

- the start-up banner after power-up, a soft reset, a replug or a restart; machine position 0
  after power-up (no homing); with ``$22=1`` power-up in Alarm (``[MSG:'$H'|'$X' to unlock]``);
- the 128-byte receive buffer: bytes beyond it are lost (``overflowed`` is set), one ``ok`` or
  ``error:N`` per line once parsed, ``parse_s`` after its end arrived (GRBL's jogging doc: 1 to
  5 ms to parse and plan a line; real-time bytes act at once, before it), an empty line gets
  ``ok``, an ``ok`` waits while the 15-block planner is full;
- real-time bytes: ``?`` a report; ``!`` a feed hold (Jog: the jog is cancelled; Run: Hold:1
  while decelerating, then Hold:0; Idle: Hold:0, suspended until ``~``); ``~`` resume; ``0x85``
  jog cancel, ignored unless in the Jog state and not already cancelling ("Command is ignored,
  if not in a JOG state or if jog cancel is already invoked and in-process"); ``0x18`` reset;
- deceleration: a hold or cancel stops after ``v / a`` (the block's rate, ``$120-$122``); a jog
  cancel reports Jog until stopped, then flushes every jog queued meanwhile and goes Idle;
- a reset while moving (Run, Jog, Home, or decelerating) raises ``ALARM:3`` and comes back in
  Alarm; ``reset_alarm=False`` reproduces what GRBL 1.1h did in 2 of 6 e-stops here (the hold
  had completed first): it comes back Idle, no alarm;
- jogs (``$J=``, G20/G21/G53/G90/G91, F required, Idle or Jog only, soft-limit error:15),
  G0/G1/M3/M4/M5/S (S reported 0 after M5), alarms that only ``$X`` or ``$H`` leave, laser mode,
- the flood coolant output (``M8`` on, ``M9`` off; ``M7`` mist is a compile option GRBL ships
  without: error:20); a reset, and an alarm that resets the motion (limits, homing: GRBL's
  ``mc_reset``), switch spindle and coolant off; the accessory field ``A:`` (S, C, F) comes
  only with the override field ``Ov:``, every 10th report and in the next one after a change
  (Interface documentation);
  motion in time (``speedup`` times faster than real time, distances unchanged: ``$$`` reports
  the rates and accelerations of that faster machine, so a driver's physics checks hold);
- a jog that becomes a cycle (``starve_segment_buffer``): when GRBL's main loop falls behind,
  the stepper interrupt finds its segment buffer empty and stops (stepper.c: ``st_go_idle``,
  ``EXEC_CYCLE_STOP``); the main loop takes that for the motion's end (protocol.c: a jog that
  is not being cancelled goes Idle, its block still planned), and its next
  ``protocol_auto_cycle_start`` finds the block and starts it as a cycle (``STATE_CYCLE``,
  reported ``Run``). From then on a jog cancel is ignored, a feed hold holds (``Hold:1``, then
  ``Hold:0``), a reset at ``Hold:0`` keeps the position without an alarm (``mc_reset`` kills
  the steppers only in a motion state or while a hold decelerates). The firmware may report
  ``Idle`` for the instant between the two; the hook makes the switch at once;
- the feed hold input pin (``press_feed_hold``: GRBL's control pin, the same as ``!``);
- a line that changes the spindle or coolant state (``M3``/``M4``/``M5``, a new ``S`` while
  on, ``M8``/``M9``) during a cycle waits for the planner to empty before it acts and is
  answered (gcode.c's ``spindle_sync``/``coolant_sync`` call ``protocol_buffer_synchronize``),
  and every line behind it waits too: ``M5`` does not switch the lamp off in ``Run``, nor
  while a hold keeps the rest of the move planned;
- faults: ``trigger_alarm``, ``unplug``/``replug``, ``restart`` (power glitch: banner, position
  0), ``reject_next`` (error codes), ``damage`` (a function that may rewrite a status line).
"""

from __future__ import annotations

from collections.abc import Callable
import os
from pathlib import Path
import random
import select
import threading
import time
import tty

from grbl_emulator_lines import GrblLines

RX_BUFFER = 128
PLANNER_BLOCKS = 15
DEFAULTS = {0: 10.0, 1: 25.0, 2: 0.0, 3: 0.0, 4: 0.0, 5: 0.0, 6: 0.0, 10: 1.0, 11: 0.010,
            12: 0.002, 13: 0.0, 20: 0.0, 21: 0.0, 22: 0.0, 23: 0.0, 24: 25.0, 25: 500.0,
            26: 250.0, 27: 1.0, 30: 1000.0, 31: 0.0, 32: 0.0, 100: 250.0, 101: 250.0,
            102: 250.0, 110: 500.0, 111: 500.0, 112: 500.0, 120: 10.0, 121: 10.0, 122: 10.0,
            130: 200.0, 131: 200.0, 132: 200.0}
REALTIME = {0x3F, 0x21, 0x7E, 0x18, 0x85}
MOVING = ('Run', 'Jog', 'Home', 'Hold:1')
LATE_S = 0.05  # a jog cancel this soon after a jog's end crossed it on the wire [s]
RESETTING_ALARMS = (1, 2, 6, 7, 8, 9)  # limits and homing failures: GRBL calls mc_reset


def random_damage(every: int, seed: int = 0) -> Callable[[str], str | None]:
    """A ``damage`` knob: every ``every``-th status line gets one byte flipped, dropped or
    inserted (seeded, so a run is repeatable)."""
    rng = random.Random(seed)
    count = 0

    def damage(line: str) -> str | None:
        nonlocal count
        count += 1
        if count % every:
            return None
        i = rng.randrange(len(line))
        char = chr(rng.randrange(32, 127))
        kind = rng.randrange(3)
        return line[:i] + (char + line[i + 1:] if kind == 0 else line[i + 1:] if kind == 1
                           else char + line[i:])
    return damage


class GrblEmulator(GrblLines):
    """One emulated controller. ``port`` is what the driver opens."""

    def __init__(self, settings: dict[int, float] | None = None, *, speedup: float = 1.0,
                 version: str = '1.1h', link_dir: str | os.PathLike | None = None,
                 reset_alarm: bool = True, parse_s: float = 0.003,
                 damage: Callable[[str], str | None] | None = None) -> None:
        self.settings = {**DEFAULTS, **(settings or {})}
        self.speedup = speedup
        self.version = version
        self.reset_alarm = reset_alarm
        self.parse_s = parse_s  # GRBL parses and plans a line in 1 to 5 ms (its jogging doc)
        self.damage = damage
        self.link = Path(link_dir) / 'ttyGRBL' if link_dir is not None else None
        self.received = b''
        self.lines: list[str] = []
        self.realtime: list[int] = []
        self.max_rx_used = 0
        self.overflowed = False
        self.state = 'Idle'
        self.mpos = (0.0, 0.0, 0.0)
        self.spindle = ('M5', 0.0)  # (mode, S as reported: 0 while off)
        self.lamp_history: list[tuple[str, float]] = []
        self.coolant = False  # the flood coolant output (the rig's photo light)
        self.coolant_history: list[bool] = []
        self._accessories_changed = False
        self.jogs: list[dict] = []  # every jog planned: target, outcome, end time
        self.cancels: list[str] = []  # what each jog cancel met: cancelled, or ignored (early,
        # late, repeat, ignored: see _cancel_outcome)
        self.damaged: list[tuple[str, str]] = []  # (status line, what was sent instead)
        self.cycles_from_jogs = 0  # jogs restarted as a cycle by a starved segment buffer
        self.reject_next: list[int] = []  # error codes to answer the next lines with (tests)
        self._lock = threading.RLock()
        self._rx = bytearray()
        self._parsed_at: list[float] = []  # when each complete line in _rx is parsed
        self._blocks: list[dict] = []  # planned moves: target, rate [mm/min], jog record
        self._segment_start = 0.0
        self._from = self.mpos
        self._stopping: dict | None = None  # a hold or jog cancel decelerating
        self._programmed_s = 0.0
        self._reports = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._master = self._slave = -1
        self.port = ''

    # --- life cycle ------------------------------------------------------------------------

    def start(self) -> GrblEmulator:
        self._open_pty()
        self._power_up()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        for fd in (self._master, self._slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = -1

    def __enter__(self) -> GrblEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _open_pty(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo or line editing before the host configures it
        name = os.ttyname(self._slave)
        if self.link is not None:
            tmp = self.link.with_suffix('.new')
            tmp.unlink(missing_ok=True)
            tmp.symlink_to(name)
            tmp.replace(self.link)
            self.port = str(self.link)
        else:
            self.port = name

    def _power_up(self) -> None:
        with self._lock:
            self._halt('power')
            self._rx.clear()
            self._parsed_at.clear()
            self.mpos = self._from = (0.0, 0.0, 0.0)  # no homing: GRBL starts at 0
            self.spindle, self._programmed_s = ('M5', 0.0), 0.0
            self._coolant(False)
            homing = self.settings[22] == 1.0
            self.state = 'Alarm' if homing else 'Idle'
            self._send(f"\r\nGrbl {self.version} ['$' for help]\r\n")
            if homing:
                self._send("[MSG:'$H'|'$X' to unlock]\r\n")

    # --- fault injection ---------------------------------------------------------------------

    def trigger_alarm(self, code: int) -> None:
        with self._lock:
            self._halt('alarm')
            if code in RESETTING_ALARMS:  # mc_reset: spindle and coolant off
                self.spindle = ('M5', 0.0)
                self._coolant(False)
            self.state = 'Alarm'
            self._send(f'ALARM:{code}\r\n')

    def starve_segment_buffer(self) -> bool:
        """The main loop fell behind the stepper interrupt during a jog: the jog goes on as a
        cycle (``Run``), as GRBL 1.1 does (see the module docstring).

        Returns:
            Whether a jog was running (a jog being cancelled ends as the cancel says instead:
            protocol.c flushes the planner on ``SUSPEND_JOG_CANCEL``).
        """
        with self._lock:
            self._move()
            if self.state != 'Jog' or self._stopping is not None or not self._blocks:
                return False
            # EXEC_CYCLE_STOP with no jog cancel: 'motion complete', Idle, planner kept; then
            # protocol_auto_cycle_start: a block is planned, EXEC_CYCLE_START: STATE_CYCLE.
            self._segment_start, self._from = time.monotonic(), self.mpos
            self.state = 'Run'
            self.cycles_from_jogs += 1
            return True

    def press_feed_hold(self) -> None:
        """The feed hold input (a button on the machine): what ``!`` does."""
        with self._lock:
            self._realtime(0x21)

    def unplug(self) -> None:
        with self._lock:
            os.close(self._master)
            os.close(self._slave)
            self._master = self._slave = -1

    def replug(self) -> None:
        """A fresh controller on the same path (its power went with the USB cable)."""
        with self._lock:
            self._open_pty()
            self._power_up()

    def restart(self) -> None:
        """The controller restarts on the same link (power glitch, reset button)."""
        self._power_up()

    def wait_idle(self, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.state == 'Idle':
                return True
            time.sleep(0.005)
        return False

    # --- the controller loop -------------------------------------------------------------------

    def _run(self) -> None:
        while not self._stop.is_set():
            fd = self._master
            if fd < 0:
                time.sleep(0.005)
                continue
            try:
                ready, _, _ = select.select([fd], [], [], 0.002)
                data = os.read(fd, 4096) if ready else b''
            except OSError:
                data = b''  # the host closed its end: wait for it to reopen
                time.sleep(0.005)
            with self._lock:
                self._move()
                for byte in data:
                    self.received += bytes([byte])
                    if byte in REALTIME:  # picked off by the serial interrupt, never buffered
                        self.realtime.append(byte)
                        self._realtime(byte)
                    elif len(self._rx) < RX_BUFFER:
                        self._rx.append(byte)
                        if byte in (0x0A, 0x0D):
                            self._parsed_at.append(time.monotonic() + self.parse_s)
                    else:
                        self.overflowed = True  # GRBL's ring buffer drops the byte
                self.max_rx_used = max(self.max_rx_used, len(self._rx))
                self._move()
                self._parse_lines()

    def _send(self, text: str) -> None:
        if self._master >= 0:
            try:
                os.write(self._master, text.encode('ascii'))
            except OSError:
                pass

    def _realtime(self, byte: int) -> None:
        if byte == 0x3F:
            self._status()
        elif byte == 0x21:  # feed hold
            if self.state == 'Jog':
                self._decelerate('cancel')
            elif self.state == 'Run':
                self._decelerate('hold')
                self.state = 'Hold:1'
            elif self.state == 'Idle':
                self.state = 'Hold:0'  # suspended: nothing runs until ~
        elif byte == 0x7E and self.state.startswith('Hold') and self._stopping is None:
            self.state = 'Run' if self._blocks else 'Idle'
            self._segment_start, self._from = time.monotonic(), self.mpos
        elif byte == 0x85:
            self.cancels.append(self._cancel_outcome())
            if self.cancels[-1] == 'cancelled':
                self._decelerate('cancel')
        elif byte == 0x18:
            self._reset()

    def _cancel_outcome(self) -> str:
        """What a jog cancel meets: acted on, or ignored (and why, for the tests)."""
        if self._stopping is not None:
            return 'repeat'  # "already invoked and in-process": ignored
        if self.state == 'Jog':
            return 'cancelled'
        if b'$J=' in self._rx:
            return 'early'  # its jog is not parsed yet: written before the jog's ok
        ended = max((j['end'] for j in self.jogs if j['end'] is not None), default=None)
        # A cancel that crossed its jog's end on the wire is a race no driver can avoid.
        return 'late' if ended is not None and time.monotonic() - ended < LATE_S else 'ignored'

    def _reset(self) -> None:
        moving = self.state in MOVING or self._stopping is not None
        if moving and not self.reset_alarm:
            self._finish_stop()  # the hold completed before the reset was handled
            moving = False
        alarm = moving or self.state == 'Alarm'
        self._halt('reset')
        self._rx.clear()
        self._parsed_at.clear()
        self.spindle = ('M5', 0.0)
        self._coolant(False)
        if moving:
            self._send('ALARM:3\r\n')
        self._send(f"\r\nGrbl {self.version} ['$' for help]\r\n")
        self.state = 'Alarm' if alarm else 'Idle'
        if alarm:
            self._send("[MSG:'$H'|'$X' to unlock]\r\n")

    def _coolant(self, on: bool) -> None:
        if on != self.coolant:
            self._accessories_changed = True
        self.coolant = on
        self.coolant_history.append(on)

    def _status(self) -> None:
        mask = int(self.settings[10])
        x, y, z = self.mpos
        pos = f'{"MPos" if mask & 1 else "WPos"}:{x:.3f},{y:.3f},{z:.3f}'
        moving = self._blocks and self.state in MOVING
        feed = self._blocks[0]['rate'] if moving else 0
        fields = [self.state, pos]
        if mask & 2:
            fields.append(f'Bf:{PLANNER_BLOCKS - len(self._blocks)},{RX_BUFFER - len(self._rx)}')
        fields.append(f'FS:{feed:.0f},{self.spindle[1]:.0f}')
        self._reports += 1
        if self._reports % 10 == 1:
            fields.append('WCO:0.000,0.000,0.000')  # the overrides wait for the next report
        elif self._reports % 10 == 2 or self._accessories_changed:
            self._accessories_changed = False
            fields.append('Ov:100,100,100')
            accessories = ('' if self.spindle[0] == 'M5' else 'S' if self.spindle[0] == 'M3'
                           else 'C') + ('F' if self.coolant else '')
            if accessories:
                fields.append('A:' + accessories)
        line = '<' + '|'.join(fields) + '>'
        damaged = self.damage(line) if self.damage is not None else None
        if damaged is not None:
            self.damaged.append((line, damaged))
            line = damaged
        self._send(line + '\r\n')

    # --- motion ----------------------------------------------------------------------------------

    def _decelerate(self, kind: str) -> None:
        """Start a hold or a jog cancel: the machine stops after v / a along its path."""
        if self._stopping is not None:
            return  # already invoked and in process: ignored
        self._move()
        if not self._blocks:
            return
        block = self._blocks[0]
        v = block['rate'] / 60.0  # mm/s, machine time
        accel = min(self.settings[120], self.settings[121], self.settings[122])
        remaining = _distance(block['target'], self.mpos)
        stop = min(remaining, v * v / (2.0 * accel))
        k = stop / remaining if remaining else 1.0
        to = tuple(p + k * (t - p) for p, t in zip(self.mpos, block['target']))
        duration = (2.0 * stop / v if v else 0.0) / self.speedup
        self._stopping = {'kind': kind, 'from': self.mpos, 'to': to,
                          't0': time.monotonic(), 'dur': duration}

    def _finish_stop(self) -> None:
        stopping, self._stopping = self._stopping, None
        if stopping is None:
            return
        self.mpos = self._from = stopping['to']
        if stopping['kind'] == 'cancel':  # flush every jog, the ones queued meanwhile too
            self._halt('cancelled')
            self.state = 'Idle'
        else:
            self.state = 'Hold:0'

    def _halt(self, outcome: str) -> None:
        """Stop where the machine is now and forget every planned block."""
        self._stopping = None
        self._move()
        for block in self._blocks:
            if block['jog'] is not None and block['jog']['outcome'] is None:
                block['jog'].update(outcome=outcome, end=time.monotonic())
        self._blocks.clear()
        self._from = self.mpos

    def _move(self) -> None:
        """Advance motion to now, block after block, at each block's constant rate."""
        now = time.monotonic()
        if self._stopping is not None:
            s = self._stopping
            k = min(1.0, (now - s['t0']) / s['dur']) if s['dur'] > 0 else 1.0
            self.mpos = tuple(f + k * (t - f) for f, t in zip(s['from'], s['to']))
            if k >= 1.0:
                self._finish_stop()
            return
        while self._blocks and self.state in ('Run', 'Jog'):
            block = self._blocks[0]
            target = block['target']
            dist = _distance(target, self._from)
            speed = block['rate'] / 60.0 * self.speedup  # mm per real second
            elapsed = now - self._segment_start
            if dist == 0 or elapsed * speed >= dist:
                self.mpos = self._from = target
                self._blocks.pop(0)
                if block['jog'] is not None:
                    block['jog'].update(outcome='done', end=now)
                self._segment_start += dist / speed if dist else 0.0
                continue
            k = elapsed * speed / dist
            self.mpos = tuple(f + k * (t - f) for t, f in zip(target, self._from))
            return
        if not self._blocks and self.state in ('Run', 'Jog'):
            self.state = 'Idle'

    def _plan(self, target: tuple[float, ...], rate: float, state: str,
              jog: dict | None = None) -> None:
        if not self._blocks:
            self._segment_start, self._from = time.monotonic(), self.mpos
        self._blocks.append({'target': target, 'rate': rate, 'jog': jog})
        if self.state == 'Idle':
            self.state = state

    # --- lines -----------------------------------------------------------------------------------

    def _parse_lines(self) -> None:
        while len(self._blocks) < PLANNER_BLOCKS:
            end = next((i for i, b in enumerate(self._rx) if b in (0x0A, 0x0D)), None)
            if end is None or time.monotonic() < self._parsed_at[0]:
                return  # GRBL takes a few ms to parse and plan a line
            if self._blocks and self.state != 'Jog' and self._synced(
                    bytes(self._rx[:end]).decode('ascii', 'replace').replace(' ', '').upper()):
                return  # spindle_sync / coolant_sync: until the planner is empty
            self._parsed_at.pop(0)
            raw = bytes(self._rx[:end])
            del self._rx[:end + 1]
            line = raw.decode('ascii', 'replace').strip()
            self.lines.append(line)
            if self.reject_next and line:
                self._send(f'error:{self.reject_next.pop(0)}\r\n')
                continue
            error = self._execute(line.replace(' ', '').upper()) if line else None
            self._send('ok\r\n' if error is None else f'error:{error}\r\n')


def _distance(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    return sum((x - y) ** 2 for x, y in zip(a, b)) ** 0.5
