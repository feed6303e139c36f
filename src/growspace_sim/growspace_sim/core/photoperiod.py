"""The photoperiod: when the chamber's lamp may be lit, and how much lit time an interval holds.

Pure arithmetic on UTC times (seconds since the epoch, ``time.time()``), so the rig
(``gantry_node``) and a replay apply the same rule. The lights-on window is given in local
STANDARD time, a fixed offset from UTC all year: daylight saving time never moves it, so the
lamp keeps the same UTC hours in summer and winter (a plant's clock would have to re-entrain
after an hour's jump; on a wall clock that keeps DST the window reads an hour later in summer).

A step's growth counts lit time only: ``growth_end(start, growth_s)`` is the first moment by
which ``growth_s`` seconds of light have passed since ``start``, so a step that would run into
the night waits, lamp off, and ends in the morning once its lit time is complete. A window may
cross midnight (``22:00`` to ``06:00``); an empty window (both times ``''``) is always lit.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import re

DAY_S = 86400.0
ROUNDING_S = 1e-3  # epoch times (~1.8e9 s) carry ~1e-7 s of rounding: a lit time this close to
# a whole number of days ends at that day's lights-off
_CLOCK = re.compile(r'([01]\d|2[0-3]):([0-5]\d)')


def clock_seconds(field: str, value: str) -> float:
    """``'HH:MM'`` (00:00 to 23:59) as seconds after midnight.

    Raises:
        ValueError: naming ``field``, the value and the form allowed.
    """
    match = _CLOCK.fullmatch(value) if isinstance(value, str) else None
    if match is None:
        raise ValueError(f'{field} = {value!r} must be a time of day HH:MM from 00:00 to 23:59')
    return 3600.0 * int(match.group(1)) + 60.0 * int(match.group(2))


@dataclass(frozen=True)
class Photoperiod:
    """A daily lights-on window in local standard time.

    Attributes:
        lights_on: ``'HH:MM'`` local standard time the lamp may go on; ``''`` (with
            ``lights_off`` ``''``): no night, always lit.
        lights_off: ``'HH:MM'`` it goes off; earlier than ``lights_on``: the window crosses
            midnight.
        utc_offset_h: local standard time minus UTC [h], fixed all year (no DST).
    """

    lights_on: str = ''
    lights_off: str = ''
    utc_offset_h: float = 0.0

    def __post_init__(self) -> None:
        if not (isinstance(self.utc_offset_h, (int, float)) and math.isfinite(self.utc_offset_h)
                and -14.0 <= self.utc_offset_h <= 14.0):
            raise ValueError(f'utc_offset_h = {self.utc_offset_h!r} must be a number of hours '
                             f'from -14.0 to 14.0')
        if (self.lights_on == '') != (self.lights_off == ''):
            raise ValueError(f'lights_on = {self.lights_on!r} and lights_off = '
                             f'{self.lights_off!r}: give both (HH:MM) or neither (always lit)')
        if self.always:
            return
        on = clock_seconds('lights_on', self.lights_on)
        off = clock_seconds('lights_off', self.lights_off)
        if on == off:
            raise ValueError(f'lights_on = lights_off = {self.lights_on!r}: a window must have '
                             f'a length (leave both empty for no night)')

    @property
    def always(self) -> bool:
        """No night: the lamp may be lit at any time."""
        return self.lights_on == '' and self.lights_off == ''

    @property
    def lit_per_day_s(self) -> float:
        """Seconds of light in a day."""
        if self.always:
            return DAY_S
        return (self._off - self._on) % DAY_S

    @property
    def _on(self) -> float:
        return clock_seconds('lights_on', self.lights_on)

    @property
    def _off(self) -> float:
        return clock_seconds('lights_off', self.lights_off)

    def is_lit(self, t: float) -> bool:
        """Whether the lamp may be lit at ``t`` [s, UTC epoch] (on at lights_on, off at
        lights_off)."""
        if self.always:
            return True
        day = (t + 3600.0 * self.utc_offset_h) % DAY_S
        on, off = self._on, self._off
        return on <= day < off if on < off else (day >= on or day < off)

    def lit_seconds(self, t0: float, t1: float) -> float:
        """Seconds of light between ``t0`` and ``t1`` [s, UTC epoch; t1 >= t0]."""
        if t1 < t0:
            raise ValueError(f'lit_seconds: t1 = {t1!r} is before t0 = {t0!r}')
        if self.always:
            return t1 - t0
        return self._lit_since_epoch(t1) - self._lit_since_epoch(t0)

    def growth_end(self, start: float, growth_s: float) -> float:
        """The first moment by which ``growth_s`` seconds of light have passed since ``start``
        [s, UTC epoch]; ``start`` itself for 0."""
        if not (math.isfinite(growth_s) and growth_s >= 0.0):
            raise ValueError(f'growth_s = {growth_s!r} must be a finite number >= 0')
        if growth_s == 0.0 or self.always:
            return start + growth_s
        lit_day = self.lit_per_day_s
        goal = self._lit_since_epoch(start) + growth_s
        days = math.floor(goal / lit_day)
        rest = goal - days * lit_day
        if rest <= ROUNDING_S:  # completed at a lights-off: that moment, not the next morning
            days, rest = days - 1, lit_day
        on, off = self._on, self._off
        if on < off:
            local = on + rest
        else:  # lit from midnight to lights_off, then from lights_on to midnight
            local = rest if rest <= off else on + (rest - off)
        return max(start, days * DAY_S + local - 3600.0 * self.utc_offset_h)

    def _lit_since_epoch(self, t: float) -> float:
        """Seconds of light from local midnight of the epoch's day to ``t``: nondecreasing."""
        local = t + 3600.0 * self.utc_offset_h
        days = math.floor(local / DAY_S)
        day = local - days * DAY_S
        on, off = self._on, self._off
        if on < off:
            today = min(max(day - on, 0.0), off - on)
        else:
            today = min(day, off) + max(day - on, 0.0)
        return days * self.lit_per_day_s + today
