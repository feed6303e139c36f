"""``python -m growspace_gym_bridge.launcher ARGS``: ``sim_node ARGS`` that ends with its parent.

A node started by a bridge env must not outlive the process that started it, however that
process ends (``close()``, an exception, SIGKILL, the OOM killer). The node watches its parent
process: once it is no longer its parent (it exited, and the node was handed to init or a
subreaper), the node stops as on SIGTERM, finishing its recording. Its closing is bounded by
``growspace_sim.node.main``'s watchdog, so a node that hangs while closing still exits.

Why not Linux's PR_SET_PDEATHSIG: it fires when the *thread* that started the child exits, so
an env created in a worker thread (a thread pool) would lose its node while the process still
uses it; and the SIGTERM it sends ends the node no sooner than this watch does.
"""

from __future__ import annotations

import os
import sys
import threading

from growspace_gym_bridge.process import PARENT_ENV

PARENT_POLL_S = 0.2  # how often the node checks that its parent still lives [s]


def watch_parent(parent_pid: int, stop: threading.Event,
                 poll_s: float = PARENT_POLL_S) -> threading.Thread:
    """Set ``stop`` as soon as ``parent_pid`` is no longer this process's parent.

    Comparing ``os.getppid()`` with the pid the parent gave is exact: once the parent exits,
    the kernel re-parents this process and never gives it the old pid back as its parent.

    Args:
        parent_pid: the pid of the process that started this one.
        stop: the node's stop flag (checked by its run loop at least every 0.1 s).
        poll_s: interval between two checks [s].

    Returns:
        The watching thread (a daemon; it ends when ``stop`` is set by anyone).
    """
    def watch() -> None:
        while os.getppid() == parent_pid:
            if stop.wait(poll_s):
                return
        print(f'sim_node: parent process {parent_pid} is gone; stopping.', file=sys.stderr)
        stop.set()

    thread = threading.Thread(target=watch, name='parent-watch', daemon=True)
    thread.start()
    return thread


def main(argv: list[str] | None = None) -> int:
    """Run ``sim_node`` with ``argv``; it stops when the parent named in the environment does."""
    from growspace_sim.node import main as node

    parent = os.environ.get(PARENT_ENV)
    if parent is None:
        return node.main(argv)

    def run(args: list[str], stop: threading.Event) -> int:
        watch_parent(int(parent), stop)
        return node.run(args, stop)
    return node.console_main(run, argv, 'sim_node stopped')


if __name__ == '__main__':
    sys.exit(main())
