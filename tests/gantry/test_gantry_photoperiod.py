"""The photoperiod (``growspace_sim.core.photoperiod``): known answers, windows across midnight,
a fixed-offset local time that DST never moves, and lit time that adds up."""

from __future__ import annotations

import calendar

import numpy as np
import pytest

from growspace_sim.core.photoperiod import DAY_S, Photoperiod

H = 3600.0
DAY0 = calendar.timegm((2026, 1, 15, 0, 0, 0))  # a UTC midnight


def at(hours: float, day: int = 0, base: float = DAY0) -> float:
    return base + day * DAY_S + hours * H


DAY = Photoperiod('06:00', '22:00')
NIGHT_CROSSING = Photoperiod('22:00', '06:00')  # lit across midnight


@pytest.mark.parametrize('period, hour, lit', [
    (DAY, 5.999, False), (DAY, 6.0, True), (DAY, 21.999, True), (DAY, 22.0, False),
    (DAY, 0.0, False), (NIGHT_CROSSING, 23.0, True), (NIGHT_CROSSING, 0.0, True),
    (NIGHT_CROSSING, 5.999, True), (NIGHT_CROSSING, 6.0, False), (NIGHT_CROSSING, 12.0, False),
    (NIGHT_CROSSING, 22.0, True), (Photoperiod(), 3.0, True)])
def test_is_lit(period, hour, lit) -> None:
    assert period.is_lit(at(hour)) is lit


def test_local_standard_time_is_a_fixed_offset_that_dst_never_moves() -> None:
    cet = Photoperiod('06:00', '22:00', utc_offset_h=1.0)  # lights on at 05:00 UTC
    for base in (DAY0, calendar.timegm((2026, 7, 15, 0, 0, 0))):  # winter, summer
        assert not cet.is_lit(at(4.99, base=base)) and cet.is_lit(at(5.0, base=base))
        assert cet.is_lit(at(20.99, base=base)) and not cet.is_lit(at(21.0, base=base))
    west = Photoperiod('20:00', '04:00', utc_offset_h=-5.0)  # 01:00 to 09:00 UTC
    assert west.is_lit(at(1.0)) and west.is_lit(at(8.99)) and not west.is_lit(at(9.0))
    assert not west.is_lit(at(0.99))


@pytest.mark.parametrize('period, t0, t1, lit_h', [
    (DAY, at(0), at(0, day=1), 16.0),
    (DAY, at(21), at(7, day=1), 2.0),  # an hour each side of the night
    (DAY, at(23), at(5, day=1), 0.0),
    (DAY, at(6), at(6, day=3), 48.0),
    (NIGHT_CROSSING, at(12), at(12, day=1), 8.0),
    (NIGHT_CROSSING, at(23), at(1, day=1), 2.0),  # across midnight, all lit
    (NIGHT_CROSSING, at(5), at(23), 2.0),
    (Photoperiod(), at(1), at(2.5), 1.5),
])
def test_lit_seconds(period, t0, t1, lit_h) -> None:
    assert period.lit_seconds(t0, t1) == pytest.approx(lit_h * H, abs=1e-3)


@pytest.mark.parametrize('period, start, growth_h, end', [
    (DAY, at(8), 2.0, at(10)),  # all in daylight
    (DAY, at(21), 1.0, at(22)),  # ends exactly at lights-off, not the next morning
    (DAY, at(21), 2.0, at(7, day=1)),  # an hour tonight, an hour tomorrow
    (DAY, at(23), 1.0, at(7, day=1)),  # started at night: the morning's first hour
    (DAY, at(3), 0.0, at(3)),  # no growth: no wait, even at night
    (DAY, at(6), 40.0, at(14, day=2)),  # 16 h a day
    (NIGHT_CROSSING, at(5), 2.0, at(23)),  # an hour before 06:00, an hour after 22:00
    (NIGHT_CROSSING, at(23), 2.0, at(1, day=1)),  # across midnight
    (NIGHT_CROSSING, at(12), 8.0, at(6, day=1)),  # the whole night's light
    (Photoperiod('06:00', '22:00', utc_offset_h=2.0), at(19), 2.0, at(5, day=1)),
    (Photoperiod(), at(23), 3.0, at(2, day=1)),
])
def test_growth_counts_only_lit_time(period, start, growth_h, end) -> None:
    assert period.growth_end(start, growth_h * H) == pytest.approx(end, abs=1e-3)


@pytest.mark.parametrize('period', [DAY, NIGHT_CROSSING, Photoperiod('07:30', '07:45', -3.5)])
def test_growth_end_is_the_first_moment_with_that_much_light(period) -> None:
    rng = np.random.default_rng(0)
    for start, growth in zip(DAY0 + rng.uniform(0, 30 * DAY_S, 200),
                             rng.uniform(0, 3 * DAY_S, 200)):
        end = period.growth_end(float(start), float(growth))
        assert period.lit_seconds(start, end) == pytest.approx(growth, abs=2e-3)
        if growth > 0:
            assert period.lit_seconds(start, end - 0.01) < growth
            assert period.is_lit(end - 0.005)  # the growth ends in the light


@pytest.mark.parametrize('kwargs, message', [
    ({'lights_on': '6:00', 'lights_off': '22:00'}, "lights_on = '6:00' must be a time of day"),
    ({'lights_on': '06:00', 'lights_off': '24:00'}, "lights_off = '24:00' must be a time"),
    ({'lights_on': '06:00'}, 'give both (HH:MM) or neither'),
    ({'lights_on': '06:00', 'lights_off': '06:00'}, 'must have a length'),
    ({'utc_offset_h': 15.0}, 'utc_offset_h = 15.0 must be a number of hours'),
    ({'utc_offset_h': float('nan')}, 'utc_offset_h = nan'),
])
def test_bad_windows_are_refused_naming_the_field(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message.replace('(', r'\(').replace(')', r'\)')):
        Photoperiod(**kwargs)


def test_bad_growth_and_interval_are_refused() -> None:
    with pytest.raises(ValueError, match='growth_s = -1.0'):
        DAY.growth_end(at(8), -1.0)
    with pytest.raises(ValueError, match='is before t0'):
        DAY.lit_seconds(at(9), at(8))
