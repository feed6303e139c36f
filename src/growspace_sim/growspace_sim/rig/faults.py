"""Fault injection for soaks and tests: the runner stops itself at a named journal line.

``GROWSPACE_RIG_PAUSE_AT=intent:N`` or ``step:N``: once the journal line of the run's Nth step
(counted over its episodes) at that stage is on disk, the process stops itself (SIGSTOP). A
harness (``scripts/soak_rig.py``, the rig tests) then injects its fault at a known point of a
fast run instead of racing it to its end. Unset in a real run. A step journaled twice does not
advance the count: ``step:N`` fires again on a duplicate of step N.
"""

from __future__ import annotations

import os
import signal
import sys

PAUSE_ENV = 'GROWSPACE_RIG_PAUSE_AT'


def armed(say: bool = False, error: type[Exception] = ValueError) -> tuple[str, int] | None:
    """The (stage, step) ``PAUSE_ENV`` names; None when it is unset.

    Args:
        say: Say on stderr that this process will stop itself.
        error: What to raise for a value it does not allow (the caller's own error).

    Raises:
        error: A value it does not allow, named.
    """
    text = os.environ.get(PAUSE_ENV, '')
    if not text:
        return None
    stage, _, number = text.partition(':')
    if stage not in ('intent', 'step') or not (number.isascii() and number.isdecimal()) \
            or int(number) < 1:
        raise error(f'{PAUSE_ENV}={text!r} is not allowed; intent:N or step:N (N >= 1), or '
                    f'unset (it is for fault injection only).')
    if say:
        print(f'{PAUSE_ENV}={text}: this process stops itself (SIGSTOP) there (fault '
              f'injection)', file=sys.stderr, flush=True)
    return stage, int(number)


def stop_if_due(point: tuple[str, int] | None, event: str, steps_done: int) -> None:
    """Stop this process (SIGSTOP) when ``event``, just journaled with ``steps_done`` steps
    complete, is ``point``'s line (an ``intent`` is for the step after them)."""
    if point is not None and point == (event, steps_done + (event == 'intent')):
        os.kill(os.getpid(), signal.SIGSTOP)
