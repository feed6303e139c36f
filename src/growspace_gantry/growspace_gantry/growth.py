"""A lockstep step's time on the rig: the move, then the growth period, then the photo.

In the simulator ``step(a_t)`` places the light and the plant grows one iteration under it, so
the observation ``s_{t+1}`` shows that growth. On the rig the same takes real time: once the
move is done, the lamp stays on at the target for ``growth_s`` seconds of LIT time (the
photoperiod, ``growspace_sim.core.photoperiod``: a step that runs into the night waits, lamp
off, and ends in the morning), and only then is the photo taken and the step answered. A reset
has no growth period (the simulator's reset observes the plant as it is).

The period ends early, by the safety rules, on any fault, an e-stop or a newer command: the
node fails the step with the reason and the lamp goes off (``safety.py``). It runs on the wall
clock (UTC, what the photoperiod is written in); a step's end is fixed when its growth starts.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from growspace_sim.core.photoperiod import Photoperiod

GROWING, NIGHT = 'growing', 'growing, night: lamp off'


@dataclass(frozen=True)
class Growing:
    """One step's growth period [s, UTC epoch]."""

    reset_id: int
    step_id: int
    start: float
    end: float  # when growth_s of lit time have passed since start


class StepTime:
    """The growth period of the lockstep step in progress, and the photoperiod's lamp.

    Args:
        growth_s: lit seconds of growth per step (``GantryParams.growth_s``; 0: none).
        photoperiod: when the lamp may be lit.
        wall_clock: UTC now [s since the epoch] (``time.time``).
    """

    def __init__(self, growth_s: float, photoperiod: Photoperiod,
                 wall_clock: Callable[[], float]) -> None:
        self.growth_s = growth_s
        self.photoperiod = photoperiod
        self.wall_clock = wall_clock
        self.growing: Growing | None = None

    @property
    def busy(self) -> bool:
        """A step is growing (its lamp on, or waiting for the morning)."""
        return self.growing is not None

    def lamp_s(self, power_s: float) -> float:
        """The lamp power for now: ``power_s`` while the photoperiod is lit, else 0."""
        return power_s if self.photoperiod.is_lit(self.wall_clock()) else 0.0

    def start(self, reset_id: int, step_id: int) -> bool:
        """The step's move is done: start its growth period. Returns False when it has none
        (``growth_s`` 0, or a reset: step_id 0), so the step is answered at once."""
        if self.growth_s <= 0.0 or step_id == 0:
            return False
        now = self.wall_clock()
        self.growing = Growing(reset_id, step_id, now,
                               self.photoperiod.growth_end(now, self.growth_s))
        return True

    def poll(self) -> Growing | None:
        """The growth period that ended now (then answer its step), else None."""
        growing = self.growing
        if growing is None or self.wall_clock() < growing.end:
            return None
        self.growing = None
        return growing

    def abandon(self) -> Growing | None:
        """End the growth period early (a fault, an e-stop, a newer command)."""
        growing, self.growing = self.growing, None
        return growing

    def phase(self) -> str:
        """'' (no growth period), ``GROWING`` or ``NIGHT`` (waiting for lights_on)."""
        if self.growing is None:
            return ''
        return GROWING if self.photoperiod.is_lit(self.wall_clock()) else NIGHT

    def left(self) -> tuple[float, float]:
        """(lit seconds of growth left, wall seconds to its end); zeros without one."""
        if self.growing is None:
            return 0.0, 0.0
        now = self.wall_clock()
        end = max(now, self.growing.end)
        return self.photoperiod.lit_seconds(now, end), end - now
