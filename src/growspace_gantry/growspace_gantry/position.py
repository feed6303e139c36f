"""Which reported machine positions to believe: damage that still looks well formed.

GRBL's serial output carries no checksum. A damaged status line usually fails to parse
(``grbl.parse_line`` checks every field it uses), but some stay well formed: on a real GRBL
1.1h here 3 of 3,308 did, e.g. ``-075.000`` for ``-275.000``. Such a position is told apart by
physics: the machine cannot have moved further since the last believed report than its fastest
rate allows in the time between, plus the latency of a report and a little slack.
"""

from __future__ import annotations

from collections.abc import Mapping
import math

LATENCY_S = 0.25  # how much older a report may be than our reading of it (serial, OS, poll) [s]
SLACK_MM = 1.0  # what two reports may differ by beyond motion (rounding, steps) [mm]
REANCHOR_AFTER = 3  # this many implausible reports in a row that agree: the machine moved

ACCEPTED, REJECTED, REANCHORED = 'accepted', 'rejected', 'reanchored'


def bound_mm(rate_mm_min: float, elapsed_s: float) -> float:
    """The furthest the machine can have moved in ``elapsed_s`` at ``rate_mm_min`` [mm]."""
    return rate_mm_min / 60.0 * (max(elapsed_s, 0.0) + LATENCY_S) + SLACK_MM


def distance(a: Mapping[str, float], b: Mapping[str, float]) -> float:
    return math.sqrt(sum((a[k] - b[k]) ** 2 for k in a))


class PositionFilter:
    """The last believed position, and whether a new report's position is plausible."""

    def __init__(self) -> None:
        self.position: dict[str, float] | None = None
        self._time = 0.0
        self._doubtful: list[dict[str, float]] = []

    def reset(self) -> None:
        """A reset, a reconnection or homing: the next report is believed as it is."""
        self.position = None
        self._doubtful.clear()

    def offer(self, position: dict[str, float], now: float, rate_mm_min: float) -> str:
        """Judge a reported position.

        Returns:
            ACCEPTED (plausible: now the believed position), REJECTED (damage: the believed
            position stays), or REANCHORED (the last REANCHOR_AFTER reports agreed with each
            other and not with the believed position: the machine was moved by something else,
            e.g. a pendant; believed from now on).
        """
        if self.position is None or distance(position, self.position) <= bound_mm(
                rate_mm_min, now - self._time):
            self._believe(position, now)
            return ACCEPTED
        if self._doubtful and distance(position, self._doubtful[-1]) > bound_mm(rate_mm_min,
                                                                                0.0):
            self._doubtful.clear()  # these do not agree with each other either
        self._doubtful.append(position)
        if len(self._doubtful) >= REANCHOR_AFTER:
            self._believe(position, now)
            return REANCHORED
        return REJECTED

    def _believe(self, position: dict[str, float], now: float) -> None:
        self.position, self._time = dict(position), now
        self._doubtful.clear()
