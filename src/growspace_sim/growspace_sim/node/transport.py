"""The seam between the node logic and the middleware.

The node, the bridge's link, teleop and the recorder are written once against ``Transport``.
Messages cross the seam as rosbags dataclasses (built by ``growspace_sim.ros.convert``)
together with their exact CDR bytes, which the recorder stores unchanged. Two implementations:
``node.rclpy_transport.RclpyTransport`` (ROS 2) and ``node.local.LocalTransport`` (in process, on
a simulated clock; ``node.fake.FakeTransport`` adds what tests inspect).

Callbacks never raise through a transport: malformed CDR is dropped before the callback and an
exception escaping a callback is caught here; both end as a throttled warning.
"""

from __future__ import annotations

from collections.abc import Callable
import time
from typing import Any, Protocol

from growspace_sim.ros import qos as ros_qos

MessageCallback = Callable[[Any, bytes], None]  # (rosbags message, CDR bytes as received)
ServiceHandler = Callable[[Any], Any]  # rosbags request -> rosbags response
ResponseCallback = Callable[[Any], None]  # called with the rosbags response of a call
PublishFn = Callable[[Any], bytes]  # publishes a message, returns the CDR bytes written
THROTTLE_S = 2.0  # one warning per key and period; a flood must not flood the log


class ThrottledLogger:
    """Log lines, with warnings throttled per key (e.g. per topic and field).

    Args:
        warn_sink: writes one warning line.
        info_sink: writes one informational line.
        period_s: minimum time between two warnings of the same key [s].
        clock: monotonic time [s]; injectable for tests.
    """

    def __init__(self, warn_sink: Callable[[str], Any], info_sink: Callable[[str], Any],
                 period_s: float = THROTTLE_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._warn_sink = warn_sink
        self._info_sink = info_sink
        self.period_s = period_s
        self._clock = clock
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}
        self._held: dict[str, str] = {}  # the last suppressed text of each key
        self.suppressed = 0  # warnings held back so far, all keys

    def warn(self, key: str, text: str) -> bool:
        """Log a warning unless one with this key was logged less than a period ago.

        Returns:
            True if the line was written.
        """
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period_s:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            self._held[key] = text
            self.suppressed += 1
            return False
        self._last[key] = now
        skipped = self._suppressed.pop(key, 0)
        self._held.pop(key, None)
        suffix = f' ({skipped} similar warnings suppressed)' if skipped else ''
        try:
            self._warn_sink(text + suffix)
        except Exception:  # noqa: BLE001 - a broken log sink must not stop the node
            pass
        return True

    def flush(self) -> None:
        """Say how many warnings each key held back once its period is over, without waiting
        for another warning of that key (which may never come)."""
        if not self._suppressed:
            return
        now = self._clock()
        for key in [k for k in self._suppressed if now - self._last[k] >= self.period_s]:
            count, text = self._suppressed.pop(key), self._held.pop(key)
            try:
                self._warn_sink(f'{count} similar warnings suppressed in the last '
                                f'{now - self._last[key]:.0f} s; the last one: {text}')
            except Exception:  # noqa: BLE001 - a broken log sink must not stop the node
                pass

    def info(self, text: str) -> None:
        try:
            self._info_sink(text)
        except Exception:  # noqa: BLE001 - same as above
            pass


class Timer(Protocol):
    """A periodic callback a transport created."""

    def set_period(self, period_s: float) -> None:
        """Call the callback every ``period_s`` seconds from now on [s]."""


class ServiceClient(Protocol):
    """The calling end of a service, asynchronous: a call never blocks the caller."""

    def ready(self) -> bool:
        """Whether a server of the service is there to answer now."""

    def call(self, request: Any, done: ResponseCallback) -> Callable[[], None]:
        """Send ``request``; ``done(response)`` runs once the answer arrives (while spinning,
        or at once in process), never if the call is cancelled or never answered (timeouts are
        the caller's). Returns a function that cancels the call."""


class Transport(Protocol):
    """What the node needs from a middleware: typed pub/sub with CDR bytes, timers, a clock."""

    logger: ThrottledLogger

    def resolve(self, topic: str) -> str:
        """Fully qualified name of a topic for this node (namespace applied)."""

    def publisher(self, typename: str, topic: str, qos: ros_qos.QosProfile) -> PublishFn:
        """Create a publisher; the returned callable publishes a message, returns its CDR."""

    def subscribe(self, typename: str, topic: str, qos: ros_qos.QosProfile,
                  callback: MessageCallback) -> None:
        """Call ``callback(msg, cdr)`` for every well-formed message received."""

    def has_subscribers(self, topic: str) -> bool:
        """Whether anyone reads what we publish on ``topic`` (the node skips unread outputs)."""

    def matched(self, topic: str) -> bool:
        """Whether our publisher or subscription on ``topic`` is matched with another node's."""

    def serve(self, srv_typename: str, name: str, handler: ServiceHandler) -> bool:
        """Offer a service; returns False where the middleware cannot."""

    def client(self, srv_typename: str, name: str) -> ServiceClient:
        """The calling end of a service (``gantry_node`` calls ``camera/capture``)."""

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> Timer:
        """Call ``callback`` every ``period_s`` seconds while spinning."""

    def spin_once(self, timeout_s: float) -> None:
        """Deliver pending messages and due timers, waiting at most ``timeout_s``."""

    def now_ns(self) -> int:
        """Wall-clock time [ns]."""

    def close(self) -> None:
        """Release every endpoint. Idempotent."""


def guarded(logger: ThrottledLogger, where: str, fn: Callable[..., Any]) -> Callable[..., None]:
    """Wrap a callback so that an exception becomes a throttled warning (the adapter boundary)."""
    def call(*args: Any) -> None:
        try:
            fn(*args)
        except Exception as e:  # noqa: BLE001 - callbacks never raise into the middleware
            logger.warn(f'callback:{where}', f'{where}: callback failed and the message was '
                        f'dropped: {type(e).__name__}: {e}')
    return call
