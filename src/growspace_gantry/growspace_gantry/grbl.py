"""GRBL 1.1 serial protocol, pure: a received line -> a typed event; a move -> the line to send.

No port, no clock, no ROS: everything here is tested with strings. What GRBL 1.1 sends (its
"Interface" documentation): one ``ok`` or ``error:N`` per line it received, status reports
``<State|Field:value|...>`` answering ``?``, ``ALARM:N``, the start-up banner ``Grbl 1.1h ['$'
for help]``, bracketed feedback (``[MSG:...]``, ``[GC:...]``, ``[VER:...]`` ...), ``$N=value``
settings lines and ``>line:ok`` start-up block echoes. Fields of a status report come and go
between reports, so they are parsed by name, never by position.

Streaming (``CharacterCounter``) follows GRBL's documented "character counting" method: a line
is sent only when it fits in what is left of the controller's 128-byte receive buffer, counting
every byte sent and not yet acknowledged by its ``ok`` / ``error``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
import math
import re

RX_BUFFER_BYTES = 128  # GRBL 1.1's serial receive buffer (the $I line [OPT:...,15,128])
MAX_LINE_BYTES = 80  # GRBL's line buffer: a longer line is refused with error:14 (1.1: 11)

# Real-time commands: single bytes, acted on at once, never answered by ok, never counted.
STATUS = b'?'
FEED_HOLD = b'!'
CYCLE_START = b'~'
SOFT_RESET = b'\x18'
JOG_CANCEL = b'\x85'

STATES = ('Idle', 'Run', 'Hold', 'Jog', 'Alarm', 'Door', 'Check', 'Home', 'Sleep')

# GRBL 1.1 error codes (its error_codes_en_US.csv), as the driver reports them.
ERRORS = {
    1: 'G-code words consist of a letter and a value; letter was not found',
    2: 'numeric value format is not valid or missing an expected value',
    3: "Grbl '$' system command was not recognized or supported",
    4: 'negative value received for an expected positive value',
    5: 'homing cycle is not enabled via settings',
    6: 'minimum step pulse time must be greater than 3 usec',
    7: 'EEPROM read failed; reset and restored to default values',
    8: "Grbl '$' command cannot be used unless Grbl is IDLE",
    9: 'G-code locked out during alarm or jog state',
    10: 'soft limits cannot be enabled without homing also enabled',
    11: 'max characters per line exceeded; line was not processed',
    12: 'Grbl setting value exceeds the maximum step rate supported',
    13: 'safety door detected as opened and door state initiated',
    14: 'build info or startup line exceeded EEPROM line length limit',
    15: 'jog target exceeds machine travel; command ignored',
    16: "jog command with no '=' or contains prohibited g-code",
    17: 'laser mode requires PWM output',
    20: 'unsupported or invalid g-code command found in block',
    21: 'more than one g-code command from same modal group found in block',
    22: 'feed rate has not yet been set or is undefined',
    23: 'g-code command in block requires an integer value',
    24: 'two g-code commands that both require the use of the XYZ axis words were detected',
    25: 'a g-code word was repeated in the block',
    26: 'a g-code command implicitly or explicitly requires XYZ axis words in the block',
    27: 'N line number value is not within the valid range of 1 - 9,999,999',
    28: 'a g-code command was sent, but is missing some required P or L value words',
    29: 'Grbl supports six work coordinate systems G54-G59; G59.1-G59.3 are not supported',
    30: 'the G53 g-code command requires either a G0 seek or G1 feed motion mode to be active',
    31: 'there are unused axis words in the block and G80 motion mode cancel is active',
    32: 'a G2 or G3 arc was commanded but there are no XYZ axis words in the selected plane',
    33: 'the motion command has an invalid target',
    34: 'a G2 or G3 arc, traced with the radius definition, had a mathematical error',
    35: 'a G2 or G3 arc, traced with the offset definition, is missing an IJK offset word',
    36: 'there are unused, leftover g-code words that are not used by any command in the block',
    37: 'the G43.1 dynamic tool length offset command cannot apply an offset to an axis '
        'other than its configured axis',
    38: 'tool number greater than max supported value',
}
# GRBL 1.1 alarm codes (alarm_codes_en_US.csv).
ALARMS = {
    1: 'hard limit triggered; machine position is likely lost, re-homing is recommended',
    2: 'soft limit: motion target exceeds machine travel; machine position retained',
    3: 'reset while in motion; machine position is likely lost, re-homing is recommended',
    4: 'probe fail: the probe is not in the expected initial state',
    5: 'probe fail: the probe did not contact the workpiece',
    6: 'homing fail: reset during active homing cycle',
    7: 'homing fail: safety door was opened during active homing cycle',
    8: 'homing fail: cycle failed to clear limit switch when pulling off',
    9: 'homing fail: could not find limit switch within search distance',
}
AXES = 'XYZ'


@dataclass(frozen=True)
class Ok:
    """``ok``: the oldest line in flight was accepted."""


@dataclass(frozen=True)
class Error:
    """``error:N``: the oldest line in flight was refused."""

    code: int

    @property
    def meaning(self) -> str:
        return ERRORS.get(self.code, 'unknown error code')


@dataclass(frozen=True)
class Alarm:
    """``ALARM:N``: the machine stopped and locks out G-code until unlocked by a person."""

    code: int

    @property
    def meaning(self) -> str:
        return ALARMS.get(self.code, 'unknown alarm code')


@dataclass(frozen=True)
class Banner:
    """The start-up line after power-up or a soft reset: nothing may be sent before it."""

    version: str  # e.g. '1.1h'


@dataclass(frozen=True)
class Status:
    """A status report ``<State|MPos:...|FS:...|...>``; fields absent from it are None."""

    state: str  # one of STATES
    substate: int | None  # Hold:0, Door:1 ...
    mpos: tuple[float, ...] | None  # machine position [mm] (reported when $10 bit 0 is set)
    wpos: tuple[float, ...] | None  # work position [mm] (reported otherwise)
    wco: tuple[float, ...] | None  # work coordinate offset [mm], sent now and then
    feed: float | None  # current feed rate [mm/min]
    speed: float | None  # current spindle speed / laser power [S units]
    planner_free: int | None  # Bf: free planner blocks
    rx_free: int | None  # Bf: free bytes in the receive buffer
    fields: Mapping[str, str] = field(default_factory=dict)  # every field, raw

    def machine_position(self, last_wco: tuple[float, ...] | None) -> tuple[float, ...] | None:
        """MPos, or WPos + WCO (the last one seen) when the report carries WPos."""
        if self.mpos is not None:
            return self.mpos
        wco = self.wco or last_wco
        if self.wpos is None or wco is None:
            return None
        return tuple(w + o for w, o in zip(self.wpos, wco))


@dataclass(frozen=True)
class Message:
    """``[MSG:text]``: feedback for a person, e.g. ``'$H'|'$X' to unlock``."""

    text: str


@dataclass(frozen=True)
class Feedback:
    """Other bracketed lines: ``[GC:...]``, ``[VER:...]``, ``[OPT:...]``, ``[HLP:...]`` ..."""

    kind: str
    text: str


@dataclass(frozen=True)
class Setting:
    """``$N=value`` (answers ``$$``)."""

    number: int
    value: float


@dataclass(frozen=True)
class StartupLine:
    """``>G54G20:ok``: a start-up block ($N0/$N1) ran; never the ``ok`` of a line we sent."""

    text: str


@dataclass(frozen=True)
class Unknown:
    """Any other line (noise on the link, an echo); logged, never taken for an answer."""

    text: str


Event = Ok | Error | Alarm | Banner | Status | Message | Feedback | Setting | StartupLine | Unknown

_BANNER = re.compile(r"^Grbl\s+(\S+)\s+\['\$' for help\]$")
_SETTING = re.compile(r'\$(\d{1,3})=(-?\d+(?:\.\d+)?)')
_CODE = re.compile(r'\d{1,3}')
_NUMBER = r'-?\d+(?:\.\d+)?'  # a rate or speed: sign, digits, maybe decimals
_COORD = r'-?\d+\.\d{3,4}'  # a coordinate: always 3 decimals in mm, 4 in inches ($13=1)
_AXES = re.compile(rf'{_COORD}(?:,{_COORD}){{2,5}}')  # 3 to 6 axes (grblHAL has up to 6)
_PAIR = re.compile(rf'({_NUMBER}),({_NUMBER})')
_FIELD_NAME = re.compile(r'[A-Z][A-Za-z]*')
SUBSTATES = {'Hold': '01', 'Door': '0123'}  # the states that carry a substate, and its values
# Alarms after which GRBL says the machine position is likely lost (re-homing recommended).
POSITION_LOST_ALARMS = frozenset({1, 3, 6, 7, 8, 9})


def _axes(fields: Mapping[str, str], name: str) -> tuple[float, ...] | None:
    if name not in fields:
        return None
    if not _AXES.fullmatch(fields[name]):
        raise ValueError(f'{name}:{fields[name]!r} is not 3 to 6 coordinates')
    return tuple(float(v) for v in fields[name].split(','))


def parse_status(body: str) -> Status:
    """Parse the inside of ``<...>``: every field that is used is checked for count and form.

    Raises:
        ValueError: an unknown state or substate, a field without a name or given twice, not
            exactly one of MPos and WPos, a position or offset that is not 3 to 6 numbers (WCO:
            as many as the position), an FS that is not two numbers, an F or Bf out of form.
    """
    parts = body.split('|')
    state, has_sub, sub = parts[0].partition(':')
    if state not in STATES:
        raise ValueError(f'unknown machine state {parts[0]!r}')
    if has_sub and not (len(sub) == 1 and sub in SUBSTATES.get(state, '')):
        raise ValueError(f'unknown substate {parts[0]!r}')
    fields: dict[str, str] = {}
    for part in parts[1:]:
        name, colon, value = part.partition(':')
        if not colon or not _FIELD_NAME.fullmatch(name) or name in fields:
            raise ValueError(f'malformed field {part!r}')
        fields[name] = value
    mpos, wpos, wco = _axes(fields, 'MPos'), _axes(fields, 'WPos'), _axes(fields, 'WCO')
    if (mpos is None) == (wpos is None):
        raise ValueError('a report carries exactly one of MPos and WPos')
    if wco is not None and len(wco) != len(mpos or wpos):
        raise ValueError('WCO and the position have different numbers of axes')
    feed = speed = None
    if 'FS' in fields:
        match = _PAIR.fullmatch(fields['FS'])
        if not match:
            raise ValueError(f'FS:{fields["FS"]!r} is not two numbers')
        feed, speed = float(match.group(1)), float(match.group(2))
    elif 'F' in fields:
        if not re.fullmatch(_NUMBER, fields['F']):
            raise ValueError(f'F:{fields["F"]!r} is not a number')
        feed = float(fields['F'])
    planner_free = rx_free = None
    if 'Bf' in fields:
        match = re.fullmatch(r'(\d+),(\d+)', fields['Bf'])
        if not match:
            raise ValueError(f'Bf:{fields["Bf"]!r} is not two counts')
        planner_free, rx_free = int(match.group(1)), int(match.group(2))
    return Status(state=state, substate=int(sub) if has_sub else None, mpos=mpos, wpos=wpos,
                  wco=wco, feed=feed, speed=speed, planner_free=planner_free, rx_free=rx_free,
                  fields=fields)


def parse_line(line: str) -> Event:
    """Turn one line received from GRBL (without its line ending) into an event.

    Never raises: a line that does not follow the protocol in every part it uses (a damaged
    line: GRBL's output has no checksum) becomes ``Unknown``.
    """
    text = line.strip()
    try:
        if text == 'ok':
            return Ok()
        if text.startswith('error:') and _CODE.fullmatch(text[6:]):
            return Error(int(text[6:]))
        if text.startswith('ALARM:') and _CODE.fullmatch(text[6:]):
            return Alarm(int(text[6:]))
        if text.startswith('<') and text.endswith('>'):
            return parse_status(text[1:-1])
        if text.startswith('[') and text.endswith(']'):
            kind, _, rest = text[1:-1].partition(':')
            return Message(rest) if kind == 'MSG' else Feedback(kind, rest)
        if text.startswith('>') and text.endswith(':ok'):
            return StartupLine(text[1:-3])
        match = _BANNER.match(text)
        if match:
            return Banner(match.group(1))
        match = _SETTING.fullmatch(text)
        if match:
            return Setting(int(match.group(1)), float(match.group(2)))
    except ValueError:
        pass
    return Unknown(text)


def alarm_text(code: int | None) -> str:
    """How an alarm is reported: ``ALARM:3 (reset while in motion; ...)``, or ``alarm (no
    code)`` for a controller found in the Alarm state without an ``ALARM:N`` line (power-up
    with homing enabled)."""
    if not code:
        return 'alarm (no code): the controller is in the Alarm state (with homing enabled it ' \
            'starts so at power-up)'
    return f'ALARM:{code} ({ALARMS.get(code, "unknown alarm code")})'


def _number(value: float) -> str:
    """A coordinate as GRBL reads it: fixed point, 3 decimals (its mm precision)."""
    text = f'{value:.3f}'
    return '0.000' if text == '-0.000' else text


def jog_line(target: Mapping[str, float], feed_mm_min: float) -> str:
    """``$J=G21G53X..Z..F..``: a jog to machine coordinates in mm (a newer jog may cancel it).

    G53 makes the target machine coordinates whatever work offset (G54..G59, G92) is active;
    the Jogging documentation allows G20/G21, G90/G91 and G53 in a jog line.

    Args:
        target: machine axis letter -> absolute machine coordinate [mm].
        feed_mm_min: the jog's feed rate [mm/min].

    Raises:
        ValueError: an unknown axis, no axis, or a value that is not finite (never sent).
    """
    if not target:
        raise ValueError('a jog needs at least one axis')
    words = []
    for axis in sorted(target):
        value = target[axis]
        if axis not in AXES:
            raise ValueError(f'axis {axis!r} is not one of {AXES}')
        if not math.isfinite(value):
            raise ValueError(f'{axis} = {value!r} mm is not finite')
        words.append(f'{axis}{_number(value)}')
    if not math.isfinite(feed_mm_min) or feed_mm_min <= 0:
        raise ValueError(f'feed = {feed_mm_min!r} mm/min must be a positive finite number')
    return f'$J=G21G53{"".join(words)}F{feed_mm_min:.0f}'


# The photo light on GRBL's flood coolant output (Arduino pin A3 on the Uno build): M8 on, M9
# off (M9 switches every coolant output off). GRBL 1.1 always has M8 (M7, mist, is a compile
# option); a reset or an alarm that resets the motion switches it off, as it does the spindle.
PHOTO_ON, PHOTO_OFF = 'M8', 'M9'


def lamp_line(power_s: float) -> str:
    """``M3 S..`` (constant power; in laser mode a new S never stops motion) or ``M5``.

    Args:
        power_s: PWM value in GRBL's S units (0 .. $30); 0 turns the lamp off with M5.

    Raises:
        ValueError: a negative or non-finite value (never sent).
    """
    if not math.isfinite(power_s) or power_s < 0:
        raise ValueError(f'lamp power S = {power_s!r} must be a finite number >= 0')
    return 'M5' if power_s == 0 else f'M3 S{power_s:.0f}'


class CharacterCounter:
    """GRBL's character-counting flow control over its receive buffer.

    Args:
        capacity: the controller's receive buffer [bytes].
    """

    def __init__(self, capacity: int = RX_BUFFER_BYTES) -> None:
        self.capacity = capacity
        self._in_flight: deque[str] = deque()
        self.used = 0  # bytes sent and not yet acknowledged

    def fits(self, line: str) -> bool:
        """Whether ``line`` (plus its newline) can be sent now."""
        return self.used + len(line) + 1 <= self.capacity

    def sent(self, line: str) -> None:
        """Count a line that was just written (with its newline)."""
        self._in_flight.append(line)
        self.used += len(line) + 1

    def acknowledged(self) -> str | None:
        """An ``ok`` or ``error`` arrived: the oldest line left the buffer; returns it."""
        if not self._in_flight:
            return None  # an answer to nothing of ours (e.g. after a reset): ignored
        line = self._in_flight.popleft()
        self.used -= len(line) + 1
        return line

    @property
    def pending(self) -> int:
        """Lines sent and not yet answered."""
        return len(self._in_flight)

    @property
    def in_flight(self) -> tuple[str, ...]:
        """The lines sent and not yet answered, oldest first."""
        return tuple(self._in_flight)

    def clear(self) -> None:
        """A soft reset or a lost link empties the controller's buffer: forget what was in it."""
        self._in_flight.clear()
        self.used = 0
