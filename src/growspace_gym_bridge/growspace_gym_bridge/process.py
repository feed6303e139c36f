"""A sim node owned by the bridge: a child process in its own namespace, always reaped."""

from __future__ import annotations

from collections.abc import Mapping
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
from typing import Any
import weakref

import growspace_sim
from growspace_sim.ros import loopback

import growspace_gym_bridge

# SIGTERM (and SIGCONT), then SIGKILL after this long [s]: longer than sim_node's own bound on
# its closing (node.main.CLOSE_TIMEOUT_S, 10 s), so a node finishing its recording on a loaded
# machine is never cut short; a hung one exits by its own watchdog first, stacks and all.
STOP_TIMEOUT_S = 12.0
TAIL_BYTES = 8192  # how much of the node's stderr an error quotes at most
PARENT_ENV = 'GROWSPACE_BRIDGE_PARENT'  # read by growspace_gym_bridge.launcher


def ros_value(value: Any) -> str:
    """A parameter value as ``-p name:=value`` text that ROS (YAML 1.1) types the same way.

    Args:
        value: a bool, int, float, str or sequence of ints.

    Returns:
        The YAML text.
    """
    if isinstance(value, float):
        text = repr(value)
        # YAML 1.1 reads 1e-05 as a string: its floats need a dot in the mantissa.
        if 'e' in text and '.' not in text.split('e')[0]:
            mantissa, exponent = text.split('e')
            text = f'{mantissa}.0e{exponent if exponent[0] in "+-" else "+" + exponent}'
        return text
    if isinstance(value, tuple):
        value = list(value)
    return json.dumps(value)  # JSON bools, ints, strings and lists are also YAML


def _package_roots() -> list[str]:
    # Source checkouts are not installed: the child must import both packages as we do.
    return [str(Path(pkg.__file__).resolve().parents[1])
            for pkg in (growspace_sim, growspace_gym_bridge)]


def _reap(proc: subprocess.Popen, timeout_s: float) -> int:
    if proc.poll() is None:
        proc.terminate()
        # A stopped (SIGSTOP, a debugger let go) node only acts on SIGTERM once it runs again.
        proc.send_signal(signal.SIGCONT)
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
    return proc.wait()


class NodeProcess:
    """Start ``sim_node`` in lockstep mode in a child process; ``stop()`` or GC reaps it.

    The child runs through ``growspace_gym_bridge.launcher``: it stops by itself once this
    process is gone, however it ended, so a crashed or killed trainer leaves no chamber behind.

    Args:
        namespace: ROS namespace of the chamber, e.g. ``/growspace_bridge_1``.
        params: node parameters (``SimConfig`` fields and node settings) as Python values.
        domain_id: ROS_DOMAIN_ID for the child; inherited when None.
        stop_timeout_s: grace period between SIGTERM and SIGKILL [s].
    """

    def __init__(self, namespace: str, params: Mapping[str, Any], *,
                 domain_id: int | None = None, stop_timeout_s: float = STOP_TIMEOUT_S) -> None:
        self.namespace = namespace
        args = ['--ros-args', '-r', f'__ns:={namespace}']
        for name, value in params.items():
            args += ['-p', f'{name}:={ros_value(value)}']
        self.argv = [sys.executable, '-m', 'growspace_gym_bridge.launcher', *args]
        env = loopback.confined_env()  # the network rule: a node we start stays on loopback
        env['PYTHONPATH'] = os.pathsep.join(
            _package_roots() + ([env['PYTHONPATH']] if env.get('PYTHONPATH') else []))
        if domain_id is not None:
            env['ROS_DOMAIN_ID'] = str(domain_id)
        env[PARENT_ENV] = str(os.getpid())
        # A file, not a pipe: nobody has to drain it, and a chatty node never blocks on it.
        self._stderr = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(self.argv, stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=self._stderr, env=env)
        self._finalizer = weakref.finalize(self, _reap, self.proc, stop_timeout_s)
        self.stop_timeout_s = stop_timeout_s

    @property
    def pid(self) -> int:
        return self.proc.pid

    def poll(self) -> int | None:
        """The exit status, or None while the node runs."""
        return self.proc.poll()

    def stderr_tail(self, lines: int = 10) -> list[str]:
        """The last lines the node wrote to stderr."""
        try:
            size = os.fstat(self._stderr.fileno()).st_size
            self._stderr.seek(max(0, size - TAIL_BYTES))
            text = self._stderr.read().decode('utf-8', 'replace')
        except (OSError, ValueError):  # closed already
            return []
        return [line for line in text.splitlines() if line.strip()][-lines:]

    def stop(self) -> int:
        """Terminate the node (SIGTERM, then SIGKILL after the grace period) and reap it.

        Returns:
            The exit status. Idempotent.
        """
        code = _reap(self.proc, self.stop_timeout_s)
        self._finalizer.detach()
        self._stderr.close()
        return code
