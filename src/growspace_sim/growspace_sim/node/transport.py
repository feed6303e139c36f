"""The seam between the node logic and the middleware, and its Cyclone DDS implementation.

The node is written once against ``Transport``. Messages cross the seam as rosbags dataclasses
(built by ``growspace_sim.convert``) together with their exact CDR bytes, which the recorder
stores unchanged. ``DdsTransport`` runs on ``growspace_sim.ros.dds`` (no ROS install needed);
``growspace_sim.node.rclpy_transport.RclpyTransport`` runs on rclpy; tests use an in-memory fake.

Callbacks never raise through a transport: malformed CDR is dropped before the callback and an
exception escaping a callback is caught here; both end as a throttled warning.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any, Callable, Protocol

from growspace_sim.ros import qos as ros_qos, types

MessageCallback = Callable[[Any, bytes], None]  # (rosbags message, CDR bytes as received)
ServiceHandler = Callable[[Any], Any]  # rosbags request -> rosbags response
PublishFn = Callable[[Any], bytes]  # publishes a message, returns the CDR bytes written
THROTTLE_S = 2.0  # one warning per key and period; a flood must not flood the log
# Asking Cyclone for matched readers costs ~10 us, so the answer is cached: a reader found is
# trusted for MATCH_CACHE_S, a topic without readers is asked again after UNMATCHED_RECHECK_S
# so a new subscriber gets outputs almost at once.
MATCH_CACHE_S = 0.5
UNMATCHED_RECHECK_S = 0.05


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

    def warn(self, key: str, text: str) -> bool:
        """Log a warning unless one with this key was logged less than a period ago.

        Returns:
            True if the line was written.
        """
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period_s:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            return False
        self._last[key] = now
        skipped = self._suppressed.pop(key, 0)
        suffix = f' ({skipped} similar warnings suppressed)' if skipped else ''
        try:
            self._warn_sink(text + suffix)
        except Exception:  # noqa: BLE001 - a broken log sink must not stop the node
            pass
        return True

    def info(self, text: str) -> None:
        try:
            self._info_sink(text)
        except Exception:  # noqa: BLE001 - same as above
            pass


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
        """Whether anyone reads what we publish on ``topic`` (may lag discovery by < 1 s)."""

    def serve(self, srv_typename: str, name: str, handler: ServiceHandler) -> bool:
        """Offer a service if the middleware can (rclpy); returns False where it cannot."""

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> None:
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


class _Timer:
    def __init__(self, period_s: float, callback: Callable[[], None], now: float) -> None:
        self.period_s = period_s
        self.callback = callback
        self.due = now + period_s


class DdsTransport:
    """``Transport`` on plain Cyclone DDS with ROS 2 wire conventions (``ros.dds.DdsContext``).

    Args:
        node_name: ROS node name.
        namespace: ROS namespace, e.g. ``/chamber1``.
        domain_id: DDS domain; ROS_DOMAIN_ID when None.
        log: the Python logger behind ``self.logger``.
    """

    def __init__(self, node_name: str, namespace: str = '/', domain_id: int | None = None,
                 log: logging.Logger | None = None) -> None:
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet

        from growspace_sim.ros import dds

        log = log or logging.getLogger(f'growspace_sim.{node_name}')
        self.logger = ThrottledLogger(log.warning, log.info)
        self.ctx = dds.DdsContext(node_name, namespace, domain_id)
        self._read_condition = ReadCondition
        self._mask = SampleState.Any | ViewState.Any | InstanceState.Any
        self._waitset = WaitSet(self.ctx.participant)
        self._conditions: list[Any] = []
        self._subs: list[tuple[Any, Callable[..., None]]] = []
        self._timers: list[_Timer] = []
        self._publishers: dict[str, Any] = {}
        self._matched: dict[str, tuple[float, bool]] = {}

    def resolve(self, topic: str) -> str:
        return self.ctx.resolve(topic)

    def publisher(self, typename: str, topic: str, qos: ros_qos.QosProfile) -> PublishFn:
        pub = self.ctx.create_publisher(typename, topic, qos)
        self._publishers[pub.topic] = pub
        return pub.publish

    def subscribe(self, typename: str, topic: str, qos: ros_qos.QosProfile,
                  callback: MessageCallback) -> None:
        sub = self.ctx.create_subscription(typename, topic, qos)
        condition = self._read_condition(sub.reader, self._mask)
        self._waitset.attach(condition)
        self._conditions.append(condition)
        self._subs.append((sub, guarded(self.logger, sub.topic, callback)))

    def has_subscribers(self, topic: str) -> bool:
        name = self.resolve(topic)
        now = time.monotonic()
        checked, matched = self._matched.get(name, (-math.inf, True))
        if now - checked > (MATCH_CACHE_S if matched else UNMATCHED_RECHECK_S):
            pub = self._publishers.get(name)
            matched = pub is not None and pub.matched_count() > 0
            self._matched[name] = (now, matched)
        return matched

    def publisher_count(self, topic: str) -> int:
        """How many remote writers our subscription on ``topic`` is matched with (0 if none)."""
        name = self.resolve(topic)
        return sum(sub.matched_count() for sub, _ in self._subs if sub.topic == name)

    def serve(self, srv_typename: str, name: str, handler: ServiceHandler) -> bool:
        # DDS services only interoperate with rmw_cyclonedds (design §1.8): topics instead.
        return False

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> None:
        self._timers.append(_Timer(period_s, guarded(self.logger, 'timer', callback),
                                   time.monotonic()))

    def spin_once(self, timeout_s: float) -> None:
        now = time.monotonic()
        wait = timeout_s
        for timer in self._timers:
            wait = min(wait, timer.due - now)
        if wait > 0:
            self._waitset.wait(int(wait * 1e9))
        for sub, callback in self._subs:
            for cdr, msg in sub.take(256):
                if isinstance(msg, types.CdrError):
                    self.logger.warn(f'cdr:{sub.topic}', f'{sub.topic}: dropped a malformed '
                                     f'message ({len(cdr)} B): {msg}')
                    continue
                callback(msg, cdr)
        now = time.monotonic()
        for timer in self._timers:
            if now >= timer.due:
                # Keep the rate on average, but never fire a burst to catch up after a stall.
                timer.due = max(timer.due + timer.period_s, now)
                timer.callback()

    def now_ns(self) -> int:
        return time.time_ns()

    def wait_for_subscribers(self, topic: str, count: int = 1, timeout_s: float = 5.0) -> bool:
        """Wait until a publisher of ours on ``topic`` has ``count`` matched readers."""
        pub = self._publishers.get(self.resolve(topic))
        return pub is not None and pub.wait_for_subscribers(count, timeout_s)

    def flush(self, timeout_s: float = 1.0) -> None:
        """Wait until every reliable reader acknowledged what we published (before exiting)."""
        for pub in self._publishers.values():
            pub.wait_for_acks(timeout_s)

    def close(self) -> None:
        # Our waitset and conditions go before the readers they watch (ros.dds closes those);
        # cyclonedds entities delete themselves once, so a later __del__ is harmless.
        for entity in (self._waitset, *self._conditions):
            try:
                entity.__del__()
            except Exception:  # noqa: BLE001 - closing goes on regardless
                pass
        self._conditions.clear()
        self._subs.clear()
        self._timers.clear()
        self.ctx.close()
