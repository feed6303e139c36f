"""The line interpreter of the test GRBL emulator: ``$`` commands, jogs and G-code.

Follows GRBL 1.1's documentation (Commands, Jogging, Laser Mode pages; its error table): a
``$`` line runs in any state it allows, a jog only in Idle or Jog (``error:8`` otherwise), other
G-code is locked out in Alarm and Jog (``error:9``). Mixed into ``GrblEmulator``, whose state
(settings, position, planner, spindle) it reads and changes.
"""

from __future__ import annotations

import re

WORD = re.compile(r'([A-Z])(-?\d*\.?\d+)')
# Settings in time units, as ``$$`` reports them for a machine ``speedup`` times faster: max and
# homing rates (mm/min) scale with it, accelerations (mm/s^2) with its square.
SCALED = {**{n: (lambda k: k) for n in (24, 25, 110, 111, 112)},
          **{n: (lambda k: k * k) for n in (120, 121, 122)}}


class GrblLines:
    """What one received line does (the emulator's state is ``self``)."""

    def _execute(self, line: str) -> int | None:
        if len(line) > 80:
            return 11
        if line == '$$':
            if self.state in ('Run',) or self.state.startswith('Hold'):
                return 8
            for number, value in sorted(self.settings.items()):
                # The machine emulated moves ``speedup`` times faster: so do its rates.
                value *= SCALED.get(number, lambda k: 1.0)(self.speedup)
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
            if self.state not in ('Idle', 'Alarm'):
                return 8
            self.mpos = self._from = (0.0, 0.0, 0.0)  # the ok comes when the cycle is done
            self.state = 'Idle'
            return None
        if line == '$I':
            self._send(f'[VER:{self.version}.20190825:]\r\n[OPT:V,15,128]\r\n')
            return None
        if line.startswith('$J='):
            return self._jog(line[3:])
        match = re.fullmatch(r'\$(\d+)=(-?\d*\.?\d+)', line)
        if match:
            if self.state not in ('Idle', 'Alarm'):
                return 8
            self.settings[int(match.group(1))] = float(match.group(2))
            return None
        if line.startswith('$'):
            return 3
        if self.state in ('Alarm', 'Jog'):
            return 9  # G-code locked out during alarm or jog state
        return self._gcode(line)

    def _synced(self, line: str) -> bool:
        """Whether GRBL waits for the planner to empty before this line (gcode.c: a change
        of the spindle state, of S while on outside a motion block, or of the coolant)."""
        words = None if line.startswith('$') else self._words(line)
        if not words:
            return False
        codes = {f'{a}{v:g}' for a, v in words if a == 'M'}
        mode = next((c for c in ('M3', 'M4', 'M5') if c in codes), self.spindle[0])
        s = [v for a, v in words if a == 'S']
        motion = any(a in 'XYZ' for a, _ in words)
        return (mode != self.spindle[0]
                or (mode != 'M5' and bool(s) and s[0] != self._programmed_s and not motion)
                or ('M8' in codes and not self.coolant) or ('M9' in codes and self.coolant))

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
            return 8  # "$J" executes only in the Idle or Jog states (its system command)
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
        record = {'target': target, 'line': f'$J={text}', 'outcome': None, 'end': None}
        self.jogs.append(record)
        # Accepted during a jog cancel too: the cancel's end flushes it (GRBL plans it first).
        self._plan(target, min(feed[0] * (25.4 if 20 in g else 1.0), self._max_rate()), 'Jog',
                   record)
        return None

    def _gcode(self, line: str) -> int | None:
        words = self._words(line)
        if words is None:
            return 1
        codes = {(a, v) for a, v in words if a in 'GM'}
        known = {('G', 0), ('G', 1), ('G', 21), ('G', 90), ('G', 94), ('M', 3), ('M', 4),
                 ('M', 5), ('M', 8), ('M', 9)}  # M7 (mist) needs a compile option
        if codes - known:
            return 20
        coolant = codes & {('M', 8), ('M', 9)}
        if len(coolant) > 1:
            return 21  # two commands of one modal group in a block
        if coolant:
            self._coolant(('M', 8) in coolant)
        s = [v for a, v in words if a == 'S']
        self._programmed_s = s[0] if s else self._programmed_s
        spindle = self.spindle
        if ('M', 5) in codes:
            self.spindle = ('M5', 0.0)
        elif ('M', 3) in codes or ('M', 4) in codes:
            self.spindle = ('M3' if ('M', 3) in codes else 'M4', self._programmed_s)
        elif s and self.spindle[0] != 'M5':
            self.spindle = (self.spindle[0], self._programmed_s)
        if self.spindle[0] != spindle[0]:
            self._accessories_changed = True
        self.lamp_history.append(self.spindle)
        if any(a in 'XYZ' for a, _ in words):
            target = self._target(words, relative=False, inches=False)
            if self.settings[20] == 1.0 and not self._within_travel(target):
                self._halt('alarm')
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
