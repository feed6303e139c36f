"""An in-memory ``Transport`` with a fake clock: the node logic without any middleware.

It mirrors the real transports at the seam (messages serialised to the same CDR bytes,
malformed bytes dropped before the callback, callback exceptions caught, services like rclpy)
so tests of everything above the seam need neither DDS nor rclpy.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any, Callable

from growspace_sim.node.transport import (
    MessageCallback, PublishFn, ServiceHandler, ThrottledLogger, guarded)
from growspace_sim.ros import names, qos as ros_qos, types


class FakeTransport:
    """``Transport`` in memory.

    Args:
        node_name: ROS node name, for name resolution.
        namespace: ROS namespace.
        services: whether ``serve`` succeeds (rclpy) or declines (DDS).
        throttle_s: warning throttle period, in fake seconds.
    """

    def __init__(self, node_name: str = 'growspace_sim', namespace: str = '/',
                 services: bool = True, throttle_s: float = 2.0) -> None:
        self.node_name = node_name
        self.namespace = namespace
        self.time_s = 0.0
        self.warnings: list[str] = []
        self.infos: list[str] = []
        self.logger = ThrottledLogger(self.warnings.append, self.infos.append, throttle_s,
                                      clock=lambda: self.time_s)
        self.published: dict[str, list[tuple[Any, bytes]]] = defaultdict(list)
        self.qos: dict[str, ros_qos.QosProfile] = {}
        self.types: dict[str, str] = {}
        self.services: dict[str, ServiceHandler] = {}
        self._accept_services = services
        self._subs: dict[str, list[tuple[str, Callable[..., None]]]] = defaultdict(list)
        self._timers: list[list[Any]] = []  # [period, due, callback]
        self.closed = False
        self.unread: set[str] = set()  # topics nobody subscribes to (has_subscribers False)

    def resolve(self, topic: str) -> str:
        return names.resolve_topic(topic, self.node_name, self.namespace)

    def publisher(self, typename: str, topic: str, qos: ros_qos.QosProfile) -> PublishFn:
        name = self.resolve(topic)
        self.qos[name] = qos
        self.types[name] = typename

        def publish(msg: Any) -> bytes:
            cdr = types.serialize(msg, typename)
            self.published[name].append((msg, cdr))
            return cdr
        return publish

    def subscribe(self, typename: str, topic: str, qos: ros_qos.QosProfile,
                  callback: MessageCallback) -> None:
        name = self.resolve(topic)
        self.qos[name] = qos
        self.types[name] = typename
        self._subs[name].append((typename, guarded(self.logger, name, callback)))

    def has_subscribers(self, topic: str) -> bool:
        return self.resolve(topic) not in self.unread

    def serve(self, srv_typename: str, name: str, handler: ServiceHandler) -> bool:
        if self._accept_services:
            self.services[name] = handler
        return self._accept_services

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> None:
        self._timers.append([period_s, self.time_s + period_s,
                             guarded(self.logger, 'timer', callback)])

    def spin_once(self, timeout_s: float) -> None:
        self.advance(timeout_s)

    def advance(self, seconds: float) -> int:
        """Move the fake clock forward, firing due timers in order; returns how many fired."""
        end = self.time_s + seconds
        fired = 0
        while self._timers:
            timer = min(self._timers, key=lambda t: t[1])
            if timer[1] > end + 1e-12:
                break
            self.time_s = timer[1]
            timer[1] += timer[0]
            timer[2]()
            fired += 1
        self.time_s = end
        return fired

    def now_ns(self) -> int:
        return int(self.time_s * 1e9)

    def close(self) -> None:
        self.closed = True

    # --- test side -----------------------------------------------------------------------

    def inject(self, topic: str, msg: Any) -> bytes:
        """Deliver a message to the subscriptions of ``topic`` as the middleware would."""
        name = self.resolve(topic)
        cdr = types.serialize(msg, self.types[name])
        self.inject_raw(topic, cdr)
        return cdr

    def inject_raw(self, topic: str, cdr: bytes) -> None:
        """Deliver raw bytes: malformed ones are dropped with a throttled warning."""
        name = self.resolve(topic)
        for typename, callback in self._subs[name]:
            try:
                msg = types.deserialize(cdr, typename)
            except types.CdrError as e:
                self.logger.warn(f'cdr:{name}', f'{name}: dropped a malformed message: {e}')
                continue
            callback(msg, cdr)

    def messages(self, topic: str) -> list[Any]:
        """Everything published on ``topic`` so far."""
        return [msg for msg, _ in self.published[self.resolve(topic)]]

    def clear(self) -> None:
        """Forget what was published."""
        self.published.clear()
