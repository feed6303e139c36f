"""``python -m growspace_gym_bridge.launcher ARGS``: ``sim_node ARGS`` that dies with its parent.

A node started by a bridge env must not outlive a trainer that crashed before ``close()``:
Linux's PR_SET_PDEATHSIG delivers SIGTERM (which the node handles like Ctrl-C) when the
thread that started it exits. Elsewhere this is plain ``sim_node``.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

from growspace_gym_bridge.process import PARENT_ENV

PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>


def die_with_parent() -> None:
    """Ask for SIGTERM when the parent dies; exit now if it already has."""
    if not sys.platform.startswith('linux'):
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM))
    except (OSError, AttributeError):  # no prctl: an orphan is then possible, not fatal
        return
    parent = os.environ.get(PARENT_ENV)
    if parent and os.getppid() != int(parent):  # the parent died before prctl took effect
        sys.exit(0)


def main() -> int:
    die_with_parent()
    from growspace_sim.node.main import main as node_main

    return node_main(sys.argv[1:])


if __name__ == '__main__':
    sys.exit(main())
