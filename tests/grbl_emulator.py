"""A GRBL 1.1 controller on a pseudo-terminal, for the gantry tests only (never shipped).

Written from GRBL 1.1's own documentation (the wiki's Interface, Commands, Jogging, Laser Mode
and Configuration pages, its error and alarm tables) and from what a real GRBL 1.1h printed
(shared/design/gantry.md), not from the driver: a shared mistake would otherwise pass.
What it models: the start-up banner (power-up, soft reset, replug), one ok/error per line when
the line is parsed, the 128-byte receive buffer and a 15-block planner (an ok waits while the
planner is full), real-time bytes (? ! ~ 0x18 0x85), status reports honouring $10, jogs
($J=, G53/G90/G91, F required, Idle or Jog only, soft-limit error:15), G0/G1/M3/M4/M5/S,
alarms that only $X or $H leave, laser mode, motion in time (constant feed, ``speedup`` times
faster than real time), an unplug (the host's reads fail) and a replug (a fresh controller).
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import select
import threading
import time
import tty

RX_BUFFER = 128
PLANNER_BLOCKS = 15
DEFAULTS = {0: 10.0, 1: 25.0, 2: 0.0, 3: 0.0, 4: 0.0, 5: 0.0, 6: 0.0, 10: 1.0, 11: 0.010,
            12: 0.002, 13: 0.0, 20: 0.0, 21: 0.0, 22: 0.0, 23: 0.0, 24: 25.0, 25: 500.0,
            26: 250.0, 27: 1.0, 30: 1000.0, 31: 0.0, 32: 0.0, 100: 250.0, 101: 250.0,
            102: 250.0, 110: 500.0, 111: 500.0, 112: 500.0, 120: 10.0, 121: 10.0, 122: 10.0,
            130: 200.0, 131: 200.0, 132: 200.0}
REALTIME = {0x3F, 0x21, 0x7E, 0x18, 0x85}
WORD = re.compile(r'([A-Z])(-?\d*\.?\d+)')


class GrblEmulator:
    """One emulated controller. ``port`` is what the driver opens."""

    def __init__(self, settings: dict[int, float] | None = None, *, speedup: float = 1.0,
                 version: str = '1.1h', link_dir: str | os.PathLike | None = None) -> None:
        self.settings = {**DEFAULTS, **(settings or {})}
        self.speedup = speedup
        self.version = version
        self.link = Path(link_dir) / 'ttyGRBL' if link_dir is not None else None
        self.received = b''
        self.lines: list[str] = []
        self.realtime: list[int] = []
        self.max_rx_used = 0
        self.overflowed = False
        self.state = 'Idle'
        self.mpos = (0.0, 0.0, 0.0)
        self.spindle = ('M5', 0.0)
        self.lamp_history: list[tuple[str, float]] = []
        self.reject_next: list[int] = []  # error codes to answer the next lines with (tests)
        self._lock = threading.RLock()
        self._rx = bytearray()
        self._blocks: list[dict] = []  # planned moves: target, rate [mm/min], jog
        self._segment_start = 0.0
        self._from = self.mpos
        self._reports = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._master = self._slave = -1
        self.port = ''

    @property
    def laser_mode(self) -> bool:
        return self.settings[32] == 1.0

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
            self._blocks.clear()
            self._rx.clear()
            self.spindle = ('M5', 0.0)
            homing = self.settings[22] == 1.0
            self.state = 'Alarm' if homing else 'Idle'
            self._send(f"\r\nGrbl {self.version} ['$' for help]\r\n")
            if homing:
                self._send("[MSG:'$H'|'$X' to unlock]\r\n")

    # --- fault injection ---------------------------------------------------------------------

    def trigger_alarm(self, code: int) -> None:
        with self._lock:
            self._halt()
            self.state = 'Alarm'
            self._send(f'ALARM:{code}\r\n')

    def unplug(self) -> None:
        with self._lock:
            os.close(self._master)
            os.close(self._slave)
            self._master = self._slave = -1

    def replug(self) -> None:
        with self._lock:
            self.mpos = (0.0, 0.0, 0.0)
            self._from = self.mpos
            self._open_pty()
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
                for byte in data:
                    self.received += bytes([byte])
                    if byte in REALTIME:
                        self.realtime.append(byte)
                        self._realtime(byte)
                    else:
                        self._rx.append(byte)
                self.max_rx_used = max(self.max_rx_used, len(self._rx))
                if len(self._rx) > RX_BUFFER:
                    self.overflowed = True
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
        elif byte == 0x21:  # feed hold: a jog is cancelled, a cycle holds
            if self.state == 'Jog':
                self._halt()
                self.state = 'Idle'
            elif self.state == 'Run':
                self._halt(keep_blocks=True)
                self.state = 'Hold:0'
        elif byte == 0x7E and self.state.startswith('Hold'):
            self.state = 'Run' if self._blocks else 'Idle'
            self._segment_start, self._from = time.monotonic(), self.mpos
        elif byte == 0x85 and self.state == 'Jog':
            self._halt()
            self.state = 'Idle'
        elif byte == 0x18:
            moving = self.state in ('Run', 'Jog', 'Home') or self.state.startswith('Hold')
            self._halt()
            self._rx.clear()
            self.spindle = ('M5', 0.0)
            if moving:
                self._send('ALARM:3\r\n')
            alarm = moving or self.state == 'Alarm'
            self._send(f"\r\nGrbl {self.version} ['$' for help]\r\n")
            self.state = 'Alarm' if alarm else 'Idle'
            if alarm:
                self._send("[MSG:'$H'|'$X' to unlock]\r\n")

    def _status(self) -> None:
        mask = int(self.settings[10])
        x, y, z = self.mpos
        pos = f'{"MPos" if mask & 1 else "WPos"}:{x:.3f},{y:.3f},{z:.3f}'
        feed = self._blocks[0]['rate'] if self._blocks and self.state in ('Run', 'Jog') else 0
        fields = [self.state, pos]
        if mask & 2:
            fields.append(f'Bf:{PLANNER_BLOCKS - len(self._blocks)},{RX_BUFFER - len(self._rx)}')
        fields.append(f'FS:{feed:.0f},{self.spindle[1]:.0f}')
        self._reports += 1
        if self._reports % 10 == 1:
            fields.append('WCO:0.000,0.000,0.000')
        if self.spindle[0] != 'M5':
            fields.append('A:' + ('S' if self.spindle[0] == 'M3' else 'C'))
        self._send('<' + '|'.join(fields) + '>\r\n')

    def _halt(self, keep_blocks: bool = False) -> None:
        self._move()
        if not keep_blocks:
            self._blocks.clear()
        self._from = self.mpos

    def _move(self) -> None:
        """Advance motion to now, block after block, at each block's constant rate."""
        now = time.monotonic()
        while self._blocks and self.state in ('Run', 'Jog'):
            block = self._blocks[0]
            target = block['target']
            dist = sum((t - f) ** 2 for t, f in zip(target, self._from)) ** 0.5
            speed = block['rate'] / 60.0 * self.speedup  # mm/s
            elapsed = now - self._segment_start
            if dist == 0 or elapsed * speed >= dist:
                self.mpos = self._from = target
                self._blocks.pop(0)
                self._segment_start += dist / speed if dist else 0.0
                continue
            k = elapsed * speed / dist
            self.mpos = tuple(f + k * (t - f) for t, f in zip(target, self._from))
            return
        if not self._blocks and self.state in ('Run', 'Jog'):
            self.state = 'Idle'

    def _parse_lines(self) -> None:
        while b'\n' in self._rx and len(self._blocks) < PLANNER_BLOCKS:
            raw, _, rest = bytes(self._rx).partition(b'\n')
            self._rx[:] = rest
            line = raw.decode('ascii', 'replace').replace('\r', '').strip()
            self.lines.append(line)
            if not line:
                continue
            if self.reject_next:
                self._send(f'error:{self.reject_next.pop(0)}\r\n')
                continue
            error = self._execute(line.replace(' ', '').upper())
            self._send('ok\r\n' if error is None else f'error:{error}\r\n')

    # --- lines ---------------------------------------------------------------------------------

    def _execute(self, line: str) -> int | None:
        if len(line) > 80:
            return 11
        if line == '$$':
            for number, value in sorted(self.settings.items()):
                text = f'{value:.3f}'.rstrip('0').rstrip('.') if value % 1 else f'{value:.0f}'
                self._send(f'${number}={text}\r\n')
            return None
        if line == '$X':
            if self.state == 'Alarm':
                self._send('[MSG:Caution: Unlocked]\r\n')
                self.state = 'Idle'
            return None
        if line == '$H':
            if self.settings[22] != 1.0:
                return 5
            self.mpos = self._from = (0.0, 0.0, 0.0)
            self.state = 'Idle'
            return None
        if line == '$I':
            self._send(f'[VER:{self.version}.20190825:]\r\n[OPT:V,15,128]\r\n')
            return None
        if line.startswith('$J='):
            return self._jog(line[3:])
        match = re.fullmatch(r'\$(\d+)=(-?\d*\.?\d+)', line)
        if match:
            if self.state != 'Idle':
                return 8
            self.settings[int(match.group(1))] = float(match.group(2))
            return None
        if line.startswith('$'):
            return 3
        if self.state in ('Alarm', 'Jog'):
            return 9  # G-code locked out during alarm or jog state
        return self._gcode(line)

    def _words(self, text: str) -> list[tuple[str, float]] | None:
        words = WORD.findall(text)
        if ''.join(f'{a}{b}' for a, b in words) != text:
            return None
        return [(a, float(b)) for a, b in words]

    def _target(self, words: list[tuple[str, float]], relative: bool, inches: bool,
                ) -> tuple[float, ...]:
        scale = 25.4 if inches else 1.0
        target = list(self.mpos if not self._blocks else self._blocks[-1]['target'])
        for letter, value in words:
            if letter in 'XYZ':
                i = 'XYZ'.index(letter)
                target[i] = target[i] + value * scale if relative else value * scale
        return tuple(target)

    def _within_travel(self, target: tuple[float, ...]) -> bool:
        return all(-self.settings[130 + i] <= v <= 0.0 for i, v in enumerate(target))

    def _jog(self, text: str) -> int | None:
        if self.state not in ('Idle', 'Jog'):
            return 9 if self.state == 'Alarm' else 8
        words = self._words(text)
        if words is None:
            return 2
        g = [v for a, v in words if a == 'G']
        if any(v not in (20, 21, 53, 90, 91) for v in g) or any(
                a not in 'GXYZF' for a, _ in words):
            return 16
        feed = [v for a, v in words if a == 'F']
        if not feed:
            return 22
        target = self._target(words, relative=91 in g and 53 not in g, inches=20 in g)
        if self.settings[20] == 1.0 and not self._within_travel(target):
            return 15
        self._plan(target, min(feed[0] * (25.4 if 20 in g else 1.0), self._max_rate()), 'Jog')
        return None

    def _gcode(self, line: str) -> int | None:
        words = self._words(line)
        if words is None:
            return 1
        codes = {(a, v) for a, v in words if a in 'GM'}
        known = {('G', 0), ('G', 1), ('G', 21), ('G', 90), ('G', 94), ('M', 3), ('M', 4),
                 ('M', 5)}
        if codes - known:
            return 20
        s = [v for a, v in words if a == 'S']
        if ('M', 5) in codes:
            self.spindle = ('M5', s[0] if s else self.spindle[1])
        elif ('M', 3) in codes or ('M', 4) in codes:
            self.spindle = ('M3' if ('M', 3) in codes else 'M4', s[0] if s else self.spindle[1])
        elif s:
            self.spindle = (self.spindle[0], s[0])
        self.lamp_history.append(self.spindle)
        if any(a in 'XYZ' for a, _ in words):
            target = self._target(words, relative=False, inches=False)
            if self.settings[20] == 1.0 and not self._within_travel(target):
                self._halt()
                self.state = 'Alarm'
                self._send('ALARM:2\r\n')
                return None
            feed = [v for a, v in words if a == 'F']
            rate = self._max_rate() if ('G', 1) not in codes else (feed[0] if feed else 0)
            if not rate:
                return 22
            self._plan(target, min(rate, self._max_rate()), 'Run')
        return None

    def _max_rate(self) -> float:
        return min(self.settings[110], self.settings[111], self.settings[112])

    def _plan(self, target: tuple[float, ...], rate: float, state: str) -> None:
        if not self._blocks:
            self._segment_start, self._from = time.monotonic(), self.mpos
        self._blocks.append({'target': target, 'rate': rate})
        self.state = state
