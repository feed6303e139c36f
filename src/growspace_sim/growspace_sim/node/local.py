"""An in-process ``Transport``: the node without middleware, on a simulated clock.

What crosses it is what crosses the real transports: messages serialised to their exact CDR
bytes (which a recorder stores), malformed bytes dropped before the callback, callback
exceptions caught. Publishing delivers to nobody (there is no one in process to deliver to);
the transport keeps only the latest message of each topic, so an in-process run of any length
holds no history. ``episode_runner`` drives a ``ChamberNode`` over it, and
``node.fake.FakeTransport`` adds what tests inspect.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
import logging
from typing import Any

from growspace_sim.node.params import DEFAULT_NODE_NAME
from growspace_sim.node.transport import (
    MessageCallback, PublishFn, ResponseCallback, ServiceHandler, ThrottledLogger, guarded)
from growspace_sim.ros import names, qos as ros_qos, types


class LocalTimer:
    """A timer on a ``LocalTransport``'s simulated clock."""

    def __init__(self, transport: LocalTransport, period_s: float,
                 callback: Callable[[], None]) -> None:
        self._transport = transport
        self.period_s = period_s
        self.due = transport.time_s + period_s  # simulated time of the next call [s]
        self.callback = callback

    def set_period(self, period_s: float) -> None:
        self.period_s = period_s
        self.due = self._transport.time_s + period_s


class LocalClient:
    """A service client in process: a call runs the handler ``serve`` registered on the same
    transport and hands its response to ``done`` at once (there is no middleware to wait on).

    Args:
        transport: The transport the server is on.
        srv_typename: ``pkg/srv/Name``.
        name: The service name, as the server gave it to ``serve``.
    """

    def __init__(self, transport: LocalTransport, srv_typename: str, name: str) -> None:
        self._transport, self.srv_typename, self.name = transport, srv_typename, name

    def ready(self) -> bool:
        return self.name in self._transport.services

    def call(self, request: Any, done: ResponseCallback) -> Callable[[], None]:
        handler = self._transport.services.get(self.name)
        if handler is None:
            return _nothing  # no server: never answered, as over a middleware
        t = self._transport
        try:
            answer = handler(t.crossing(request, f'{self.srv_typename}_Request'))
        except Exception as e:  # noqa: BLE001 - as RclpyTransport.serve: an empty answer
            t.logger.warn(f'srv:{self.name}', f'{self.name}: service call failed: {e}')
            answer = types.new(f'{self.srv_typename}_Response')
        response = t.crossing(answer, f'{self.srv_typename}_Response')
        guarded(t.logger, f'client:{self.name}', done)(response)
        return _nothing


def _nothing() -> None:
    """Cancelling a call that is already answered."""


class LocalTransport:
    """``Transport`` in process.

    Args:
        node_name: ROS node name, for name resolution.
        namespace: ROS namespace.
        services: whether ``serve`` succeeds (as rclpy) or declines.
        logger: where warnings go; by default Python logging, throttled in wall time.
    """

    def __init__(self, node_name: str = DEFAULT_NODE_NAME, namespace: str = '/', *,
                 services: bool = True, logger: ThrottledLogger | None = None) -> None:
        self.node_name = node_name
        self.namespace = names.normalize_namespace(namespace)
        if logger is None:
            log = logging.getLogger(f'growspace_sim.{node_name}')
            logger = ThrottledLogger(log.warning, log.info)
        self.logger = logger
        self.time_s = 0.0  # the simulated clock that timers run on [s]
        self.latest: dict[str, Any] = {}  # fully qualified topic -> last message published
        self.services: dict[str, ServiceHandler] = {}
        self.closed = False
        self._accept_services = services
        self._types: dict[str, str] = {}
        self._subs: dict[str, list[tuple[str, Callable[..., None]]]] = defaultdict(list)
        self._timers: list[LocalTimer] = []
        self._resolved: dict[str, str] = {}

    def resolve(self, topic: str) -> str:
        name = self._resolved.get(topic)
        if name is None:  # resolving costs ~15 us; a lockstep runner resolves every step
            name = self._resolved[topic] = names.resolve_topic(topic, self.node_name,
                                                               self.namespace)
        return name

    def publisher(self, typename: str, topic: str, qos: ros_qos.QosProfile) -> PublishFn:
        name = self.resolve(topic)
        self._types[name] = typename
        serialize, published = types.serialize, self._published

        def publish(msg: Any) -> bytes:
            cdr = serialize(msg, typename)
            published(name, msg, cdr)
            return cdr
        return publish

    def _published(self, name: str, msg: Any, cdr: bytes) -> None:
        self.latest[name] = msg

    def subscribe(self, typename: str, topic: str, qos: ros_qos.QosProfile,
                  callback: MessageCallback) -> None:
        name = self.resolve(topic)
        self._types[name] = typename
        self._subs[name].append((typename, guarded(self.logger, name, callback)))

    def has_subscribers(self, topic: str) -> bool:
        return True  # in process, the caller reads every output

    def matched(self, topic: str) -> bool:
        return True  # the caller is the other end

    def serve(self, srv_typename: str, name: str, handler: ServiceHandler) -> bool:
        if self._accept_services:
            self.services[name] = handler
        return self._accept_services

    def client(self, srv_typename: str, name: str) -> LocalClient:
        return LocalClient(self, srv_typename, name)

    def crossing(self, msg: Any, typename: str) -> Any:
        """A message as it arrives at the other end of a service call (in process: itself)."""
        return msg

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> LocalTimer:
        timer = LocalTimer(self, period_s, guarded(self.logger, 'timer', callback))
        self._timers.append(timer)
        return timer

    def spin_once(self, timeout_s: float) -> None:
        self.advance(timeout_s)

    def advance(self, seconds: float) -> int:
        """Move the clock forward, firing due timers in order; returns how many fired."""
        end = self.time_s + seconds
        fired = 0
        while self._timers:
            timer = min(self._timers, key=lambda t: t.due)
            if timer.due > end + 1e-12:
                break
            self.time_s = timer.due
            timer.due += timer.period_s
            timer.callback()
            fired += 1
        self.time_s = end
        return fired

    def now_ns(self) -> int:
        return int(self.time_s * 1e9)

    def close(self) -> None:
        self.closed = True

    # --- the sending side ----------------------------------------------------------------

    def inject(self, topic: str, msg: Any) -> bytes:
        """Deliver a message built in process to the subscriptions of ``topic``.

        It is serialised once (the subscriber records those bytes) and handed over as it is:
        decoding bytes we just encoded would only cost time. ``FakeTransport`` decodes them.

        Returns:
            The CDR bytes delivered.
        """
        name = self.resolve(topic)
        cdr = types.serialize(msg, self._types[name])
        for _, callback in self._subs[name]:
            callback(msg, cdr)
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
