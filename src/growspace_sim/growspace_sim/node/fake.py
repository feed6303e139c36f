"""The in-process transport with what tests inspect: every message published, warnings kept.

``LocalTransport`` already mirrors the real transports at the seam (messages serialised to the
same CDR bytes, malformed bytes dropped before the callback, callback exceptions caught, services
like rclpy); this adds the history, a warning log on the simulated clock and topics that can be
marked unread, so tests of everything above the seam need no rclpy.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from growspace_sim.node.local import LocalTransport
from growspace_sim.node.transport import MessageCallback, PublishFn, ThrottledLogger
from growspace_sim.ros import qos as ros_qos, types


class FakeTransport(LocalTransport):
    """``LocalTransport`` that keeps everything for inspection.

    Args:
        node_name: ROS node name, for name resolution.
        namespace: ROS namespace.
        services: whether ``serve`` succeeds (rclpy) or declines.
        throttle_s: warning throttle period, in simulated seconds.
    """

    def __init__(self, node_name: str = 'growspace_sim', namespace: str = '/',
                 services: bool = True, throttle_s: float = 2.0) -> None:
        self.warnings: list[str] = []
        self.infos: list[str] = []
        super().__init__(node_name, namespace, services=services, logger=ThrottledLogger(
            self.warnings.append, self.infos.append, throttle_s, clock=lambda: self.time_s))
        self.published: dict[str, list[tuple[Any, bytes]]] = defaultdict(list)
        self.sequence: list[str] = []  # every topic published to, in publishing order
        self.qos: dict[str, ros_qos.QosProfile] = {}
        self.unread: set[str] = set()  # topics nobody subscribes to (has_subscribers False)

    @property
    def types(self) -> dict[str, str]:
        """Fully qualified topic -> message type, for every endpoint."""
        return self._types

    def publisher(self, typename: str, topic: str, qos: ros_qos.QosProfile) -> PublishFn:
        self.qos[self.resolve(topic)] = qos
        return super().publisher(typename, topic, qos)

    def _published(self, name: str, msg: Any, cdr: bytes) -> None:
        super()._published(name, msg, cdr)
        self.published[name].append((msg, cdr))
        self.sequence.append(name)

    def subscribe(self, typename: str, topic: str, qos: ros_qos.QosProfile,
                  callback: MessageCallback) -> None:
        self.qos[self.resolve(topic)] = qos
        super().subscribe(typename, topic, qos, callback)

    def has_subscribers(self, topic: str) -> bool:
        return self.resolve(topic) not in self.unread

    def inject(self, topic: str, msg: Any) -> bytes:
        """Deliver a message to the subscriptions of ``topic`` as the middleware would.

        Unlike ``LocalTransport.inject`` the bytes are decoded again, so tests see exactly
        what a node on rclpy would get.

        Returns:
            The CDR bytes delivered.
        """
        cdr = types.serialize(msg, self.types[self.resolve(topic)])
        self.inject_raw(topic, cdr)
        return cdr

    def crossing(self, msg: Any, typename: str) -> Any:
        """Service requests and responses through the codec both ways, as over rclpy."""
        return types.deserialize(types.serialize(msg, typename), typename)

    def messages(self, topic: str) -> list[Any]:
        """Everything published on ``topic`` so far."""
        return [msg for msg, _ in self.published[self.resolve(topic)]]

    def clear(self) -> None:
        """Forget what was published."""
        self.published.clear()
