"""The run's photoperiod on the runner's side: a step is begun only while the lamp may be lit.

Where the chamber has no photoperiod of its own (``sim_node``), ``growspace-rig run
--lights-on HH:MM --lights-off HH:MM`` holds a step that would begin in the night until the next
lights-on, so a simulated run keeps the rig's day (``Runner``'s ``not_before`` hook). The rule
is the rig's own (``growspace_sim.core.photoperiod``: local standard time at a fixed UTC offset,
never moved by DST). On ``gantry_node`` leave it out and set the gantry's ``lights_on`` /
``lights_off``: the gantry then lets a step's growth period wait, lamp off, for the morning
(``growspace_gantry.growth``), which a step begun just before the night needs as well.
"""

from __future__ import annotations

from collections.abc import Callable
import datetime as dt

from growspace_sim.core.photoperiod import clock_seconds, DAY_S, Photoperiod


def next_lit(period: Photoperiod, at: dt.datetime) -> dt.datetime:
    """``at`` itself while lit, else the next lights-on (aware UTC datetimes)."""
    t = at.timestamp()
    if period.is_lit(t):
        return at
    day = (t + 3600.0 * period.utc_offset_h) % DAY_S
    wait = (clock_seconds('lights_on', period.lights_on) - day) % DAY_S
    return at + dt.timedelta(seconds=wait)


def hold_for(period: Photoperiod) -> Callable[[dt.datetime], dt.datetime] | None:
    """The runner's ``not_before`` for a photoperiod; None when always lit."""
    if period.always:
        return None
    return lambda at: next_lit(period, at)
