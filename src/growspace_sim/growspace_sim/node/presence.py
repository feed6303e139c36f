"""Saying so when no chamber answers where a program looks for one.

A view, a teleop or a recorder started in another namespace than the chamber's would otherwise
wait in silence; after ``AFTER_S`` without the chamber's latched ``chamber/config`` it logs
one line naming the namespace it looks in and those where the ROS graph shows chambers.
"""

from __future__ import annotations

from collections.abc import Callable
import time
from typing import Any

AFTER_S = 5.0  # how long a program waits for its chamber before it says so [s]


def where_chambers_are(transport: Any) -> str:
    """'chambers are in /a, /b' or 'no chamber is on the ROS graph (...)', for a message."""
    found = transport.chamber_namespaces()
    if found:
        return f'chambers are in {", ".join(found)} (-r __ns:=NAMESPACE picks one)'
    return ('no chamber is on the ROS graph (is sim_node or gantry_node running, with the same '
            'ROS_DOMAIN_ID?)')


class ChamberWatch:
    """Call ``seen()`` when the chamber shows itself and ``check()`` now and then.

    Args:
        transport: an ``RclpyTransport`` (its ``chamber_namespaces`` and ``resolve``).
        program: who is waiting, for the message (e.g. ``view_node``).
        say: where the one line goes (a logger's warning, ``print`` to stderr).
        after_s: how long to wait before saying so.
    """

    def __init__(self, transport: Any, program: str, say: Callable[[str], None],
                 after_s: float = AFTER_S) -> None:
        self.transport, self.program, self.say = transport, program, say
        self._deadline = time.monotonic() + after_s
        self._after_s = after_s
        self.found = False
        self.said = False

    def seen(self) -> None:
        self.found = True

    def check(self) -> None:
        """Say it once, ``after_s`` after the start, if the chamber has not shown itself."""
        if self.found or self.said or time.monotonic() < self._deadline:
            return
        self.said = True
        namespace = self.transport.resolve('chamber/config').rsplit('/chamber/config', 1)[0]
        self.say(f'{self.program}: no chamber in {namespace or "/"} after '
                 f'{self._after_s:g} s; {where_chambers_are(self.transport)}.')
