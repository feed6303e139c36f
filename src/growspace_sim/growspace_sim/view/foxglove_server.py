"""The chamber's topics over the Foxglove WebSocket protocol, with the light as the only input.

Built on the ``foxglove-sdk`` package's server (``foxglove.start_server``), in a private
``foxglove.Context``. Every channel carries ROS 2 messages as CDR (the exact bytes received on
the ROS topic) with the ``ros2msg`` schema our MCAP recorder writes (``ros.types.msgdef``), so
the Foxglove app decodes them as it decodes our recordings, with no ROS install on its side.

Clients may publish (capability ClientPublish, encoding ``cdr``) on the light's command topic
and the reset topic only, with the right schema name; any other channel a client advertises is
refused with an error status naming the topic and what is accepted, and its data is dropped.
The chamber's ``Reset`` service is offered as a Foxglove service (capability Services).
Binds 127.0.0.1 unless told otherwise: another address exposes the light and reset to anyone
who can reach it, with no authentication.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
import logging
import threading
from typing import Any

import foxglove
from foxglove.websocket import Capability, ChannelView, Client, ClientChannel, StatusLevel

from growspace_sim.ros import types

ENCODING = 'cdr'
SCHEMA_ENCODING = 'ros2msg'
DEFAULT_HOST = '127.0.0.1'

log = logging.getLogger('growspace_sim.view.foxglove')

InputHandler = Callable[[str, Any], None]  # (topic as served, decoded rosbags message)
ServiceFn = Callable[[Any], Any]  # rosbags request -> rosbags response


def schema(typename: str) -> foxglove.Schema:
    """The ``ros2msg`` schema of a type, as our MCAP recorder writes it."""
    return foxglove.Schema(name=typename, encoding=SCHEMA_ENCODING,
                           data=types.msgdef(typename).encode())


class FoxgloveServer:
    """A Foxglove WebSocket server for one chamber.

    Args:
        outputs: (topic, type) of every channel served, e.g. ``('/growspace/step_result',
            'growspace_msgs/msg/StepResult')``.
        inputs: topic -> type of the channels clients may publish on.
        on_input: called with (topic, message) for every well-formed client message, in the
            server's thread.
        services: name -> (service type, handler) offered to clients, e.g.
            ``{'/growspace/reset': ('growspace_msgs/srv/Reset', fn)}``.
        host: address to bind; 127.0.0.1 keeps it on this machine.
        port: TCP port; 0 picks a free one (``port`` tells which).
        name: the server name clients show.

    Raises:
        RuntimeError: the server cannot start (port in use, bad address).
    """

    def __init__(self, outputs: Sequence[tuple[str, str]], inputs: Mapping[str, str],
                 on_input: InputHandler, *,
                 services: Mapping[str, tuple[str, ServiceFn]] | None = None,
                 host: str = DEFAULT_HOST, port: int = 0, name: str = 'growspace') -> None:
        self.context = foxglove.Context()
        self.inputs = dict(inputs)
        self._on_input = on_input
        self._accepted: dict[tuple[int, int], tuple[str, str]] = {}
        self._lock = threading.Lock()
        self.refused: list[str] = []  # topics of refused client channels (tests, logs)
        self.channels = {
            topic: foxglove.Channel(topic, schema=schema(typename), message_encoding=ENCODING,
                                    context=self.context)
            for topic, typename in outputs}
        foxglove_services = [self._service(n, t, fn) for n, (t, fn) in (services or {}).items()]
        try:
            self.server = foxglove.start_server(
                name=name, host=host, port=port, context=self.context,
                capabilities=[Capability.ClientPublish, Capability.Services],
                supported_encodings=[ENCODING], server_listener=self,
                services=foxglove_services)
        except Exception as e:  # noqa: BLE001 - the SDK raises its own error types
            raise RuntimeError(f'cannot start the Foxglove server on {host}:{port}: {e}') \
                from None
        self.host = host

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return self.server.port

    def wants(self, topic: str) -> bool:
        """Whether a client subscribes to ``topic`` (unread channels are not logged)."""
        channel = self.channels.get(topic)
        return channel is not None and channel.has_sinks()

    def log(self, topic: str, cdr: bytes, log_time_ns: int | None = None) -> None:
        """Send CDR bytes to the clients subscribed to ``topic``."""
        channel = self.channels.get(topic)
        if channel is not None:
            channel.log(bytes(cdr), log_time=log_time_ns)

    def close(self) -> None:
        """Stop the server (clients are disconnected). Idempotent."""
        self.server.stop()

    def _service(self, name: str, srv_type: str, handler: ServiceFn) -> foxglove.Service:
        request, response = f'{srv_type}_Request', f'{srv_type}_Response'

        def call(req: foxglove.ServiceRequest) -> bytes:
            msg = types.deserialize(req.payload, request)  # CdrError: the client gets it
            return types.serialize(handler(msg), response)

        def message_schema(typename: str) -> foxglove.MessageSchema:
            return foxglove.MessageSchema(encoding=ENCODING, schema=schema(typename))
        return foxglove.Service(name, schema=foxglove.ServiceSchema(
            srv_type, request=message_schema(request), response=message_schema(response)),
            handler=call)

    # --- foxglove.websocket.ServerListener -----------------------------------------------

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        log.debug('client %s subscribed to %s', client.id, channel.topic)

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        log.debug('client %s unsubscribed from %s', client.id, channel.topic)

    def on_client_advertise(self, client: Client, channel: ClientChannel) -> None:
        typename = self.inputs.get(channel.topic)
        if typename is None or channel.encoding != ENCODING or channel.schema_name != typename:
            allowed = ', '.join(f'{t} ({n}, {ENCODING})' for t, n in self.inputs.items())
            text = (f'refused client channel {channel.topic!r} ({channel.encoding}, '
                    f'{channel.schema_name}): this server accepts publishing only on {allowed}')
            with self._lock:
                self.refused.append(channel.topic)
            log.warning(text)
            self.server.publish_status(text, StatusLevel.Error, id=f'refused:{channel.topic}')
            return
        with self._lock:
            self._accepted[(client.id, channel.id)] = (channel.topic, typename)

    def on_client_unadvertise(self, client: Client, client_channel_id: int) -> None:
        with self._lock:
            self._accepted.pop((client.id, client_channel_id), None)

    def on_message_data(self, client: Client, client_channel_id: int, data: bytes) -> None:
        with self._lock:
            accepted = self._accepted.get((client.id, client_channel_id))
        if accepted is None:
            return  # a refused channel: its status message was sent on advertise
        topic, typename = accepted
        try:
            msg = types.deserialize(data, typename)
        except types.CdrError as e:
            self.server.publish_status(f'{topic}: dropped a malformed message: {e}',
                                       StatusLevel.Warning, id=f'cdr:{topic}')
            return
        try:
            self._on_input(topic, msg)
        except Exception as e:  # noqa: BLE001 - a client's message never stops the server
            log.warning('%s: client message not forwarded: %s', topic, e)
