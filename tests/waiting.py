"""Waiting for an event in a test: poll a condition up to a generous deadline, never a fixed
time that assumes the event came by then (a loaded machine makes every such guess wrong)."""

from __future__ import annotations

from collections.abc import Callable
import time
from typing import TypeVar

T = TypeVar('T')


def wait_until(predicate: Callable[[], T], timeout: float, what: str, *,
               between: Callable[[], object] | None = None,
               detail: Callable[[], str] | None = None) -> T:
    """Poll ``predicate`` until it returns something true; returns that value.

    Args:
        predicate: The event's check. It may also act, where only a retry shows the event
            (a request sent again until its answer comes).
        timeout: The deadline [s], generous: it bounds a failing test, not a passing one.
        what: The event, as a sentence: 'the view says where the chambers are'.
        between: Called between two checks (an executor's ``spin_once``, reading a pipe);
            None = sleep 50 ms.
        detail: Called on failure for more context (a process's output tail).

    Raises:
        AssertionError: ``what`` did not happen within ``timeout`` (with ``detail()``).
    """
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f'waited {timeout:g} s in vain for: {what}'
                                 + (f'\n{detail()}' if detail is not None else ''))
        if between is None:
            time.sleep(0.05)
        else:
            between()


class LinkLines:
    """The lines a test reads back from a controller's link, and a wait for the next one that
    matches (a link: ``write(bytes)`` and ``read_lines()``, as ``growspace_gantry.link``'s).

    Attributes:
        seen: Every line read so far, in order.
    """

    def __init__(self, link, timeout: float = 5.0) -> None:  # noqa: ANN001 - any such link
        self.link = link
        self.timeout = timeout
        self.seen: list[str] = []

    def until(self, predicate: Callable[[str], bool], send: bytes | None = None) -> str:
        """Send ``send`` (if any), then read lines until one matches; returns it."""
        if send is not None:
            self.link.write(send)
        found: list[str] = []

        def matched() -> bool:
            for line in self.link.read_lines():
                self.seen.append(line)
                if predicate(line):
                    found.append(line)
                    return True
            return False

        wait_until(matched, self.timeout, 'a matching line from the controller',
                   between=lambda: time.sleep(0.002), detail=lambda: f'got {self.seen[-5:]}')
        return found[0]
