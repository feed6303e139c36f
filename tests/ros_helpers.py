"""Real ROS 2 pieces for tests: the installed ``sim_node`` executable and an rclpy client.

The client uses the rosidl-generated ``growspace_msgs`` and ``sensor_msgs`` classes, as any ROS
user's node would, so these tests check our node against rclpy itself, not against our codec.
"""

from __future__ import annotations

from collections.abc import Callable
import signal
import subprocess
import tempfile
import time
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.signals import SignalHandlerOptions

from growspace_msgs.msg import LightCommand, ResetRequest, StepResult
from sensor_msgs.msg import Image
from std_msgs.msg import String

from growspace_sim.node.main import installed_executable as sim_node_executable
from growspace_sim.node.rclpy_transport import RclpyTransport
from growspace_sim.ros.interface import COMMAND_QOS
from waiting import wait_until

TIMEOUT_S = 60.0  # for events that surely come: generous for a loaded 2-core machine
COMMANDS = QoSProfile(depth=100)
OBSERVATIONS = QoSProfile(depth=10)
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)  # chamber/config


def wait_until_idle(namespace: str, timeout_s: float = 30.0) -> None:
    """Until gantry_node in ``namespace`` reports its controller Idle (connected, settings
    checked): before that it refuses a reset (``gantry not ready``), as it should."""
    listener = RclpyTransport('idle_listener', namespace)
    try:
        idle: list = []
        listener.subscribe('diagnostic_msgs/msg/DiagnosticArray', 'gantry/status', COMMAND_QOS,
                           lambda m, _: idle.extend(s for s in m.status
                                                    if s.message.startswith('Idle')))
        wait_until(lambda: idle, timeout_s, f'gantry_node in {namespace} reports Idle',
                   between=lambda: listener.spin_once(0.05))
    finally:
        listener.close()


class NodeProcess:
    """``sim_node`` as a child process; always killed at the end.

    Its output goes to a file, not a pipe: nobody reads a pipe while the node runs, and a chatty
    node would block once the pipe is full.
    """

    def __init__(self, *ros_args: str, namespace: str | None = '/gs_test',
                 executable: str | None = None) -> None:
        remap = ['-r', f'__ns:={namespace}'] if namespace else []
        self.argv = [executable or sim_node_executable(), '--ros-args', *remap, *ros_args]
        self._out = tempfile.TemporaryFile('w+')  # closed in stop()
        self._log = ''
        self.proc = subprocess.Popen(self.argv, stdout=self._out, stderr=subprocess.STDOUT,
                                     text=True)

    def output(self) -> str:
        """Everything the node wrote so far (stdout and stderr)."""
        self._out.seek(0)
        return self._out.read()

    def stop(self, sig: int = signal.SIGTERM) -> tuple[int, str]:
        """Send ``sig``, wait; returns the exit status and everything the node logged.

        A second call (a ``finally`` after the test's own stop) returns the first result.
        """
        if self._out.closed:
            return self.proc.returncode, self._log
        try:
            if self.proc.poll() is None:
                self.proc.send_signal(sig)
            self.proc.wait(timeout=TIMEOUT_S)
            self._log = self.output()
            return self.proc.returncode, self._log
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
            self._out.close()


class Client:
    """A lockstep client on rclpy with the generated message classes, in a private context."""

    def __init__(self, namespace: str = '/gs_test', name: str = 'test_client', *,
                 observe: bool = True) -> None:
        """``observe=False``: no subscriptions of its own (a test whose only readers of the
        chamber's topics must be the ones it makes, as an RViz would)."""
        self.context = Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node(name, namespace=namespace, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.command = self.node.create_publisher(LightCommand, 'light/command', COMMANDS)
        self.reset_pub = self.node.create_publisher(ResetRequest, 'reset', COMMANDS)
        self.results: list[StepResult] = []
        self.images: list[Image] = []
        self.configs: list[String] = []
        if observe:
            self.node.create_subscription(StepResult, 'step_result', self.results.append,
                                          OBSERVATIONS)
            self.node.create_subscription(Image, 'camera/image_raw', self.images.append,
                                          OBSERVATIONS)
            # Last: our endpoints reach the node in the order they were made, so its latched
            # config arriving here shows it has matched the subscriptions above as well.
            self.node.create_subscription(String, 'chamber/config', self.configs.append,
                                          LATCHED)

    def spin_until(self, predicate: Callable[[], bool], timeout: float = TIMEOUT_S) -> bool:
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def wait_until(self, predicate: Callable[[], Any], timeout: float, what: str) -> Any:
        """``waiting.wait_until`` spinning this client between checks."""
        return wait_until(predicate, timeout, what,
                          between=lambda: self.executor.spin_once(timeout_sec=0.05))

    def connect(self) -> None:
        """Until our endpoints and the node's have matched both ways (the node's latched
        config reached us: its writers know our readers)."""
        self.wait_until(lambda: self.command.get_subscription_count() > 0
                        and self.reset_pub.get_subscription_count() > 0
                        and self.configs, 3 * TIMEOUT_S, 'the node appears and matches ours')

    def reset_until(self, arrived: Callable[[int], bool], first_id: int, what: str,
                    **fields: Any) -> int:
        """Resets (ids ``first_id``, +1, ...) until ``arrived(reset_id)``: for a reader made
        after ``connect()``, its answer reaching it shows the node's writer knows it. Returns
        the reset id that arrived."""
        sent = [first_id - 1]

        def reached() -> bool:
            sent[0] += 1
            self.reset_pub.publish(ResetRequest(reset_id=sent[0], **fields))
            return self.spin_until(lambda: arrived(sent[0]), 2.0)
        self.wait_until(reached, 3 * TIMEOUT_S, what)
        return sent[0]

    def wait_result(self, match: Callable[[StepResult], bool], since: int = 0,
                    timeout: float = TIMEOUT_S) -> StepResult:
        """The first StepResult from ``self.results[since:]`` that ``match`` accepts."""
        def found() -> StepResult | None:
            return next((r for r in self.results[since:] if match(r)), None)
        assert self.spin_until(lambda: found() is not None, timeout), \
            'no matching StepResult in time'
        return found()

    def reset(self, reset_id: int, **fields: Any) -> StepResult:
        since = len(self.results)
        self.reset_pub.publish(ResetRequest(reset_id=reset_id, **fields))
        return self.wait_result(lambda m: m.reset_id == reset_id and m.step_id == 0, since)

    def step(self, step_id: int, action: int) -> StepResult:
        since = len(self.results)
        self.command.publish(LightCommand(step_id=step_id, mode=LightCommand.MODE_DISCRETE,
                                          action=action))
        return self.wait_result(lambda m: m.step_id == step_id, since)

    def drain(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()
