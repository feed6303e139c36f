"""A ROS 2 node's endpoints on plain Cyclone DDS, wire-compatible with rmw_cyclonedds_cpp.

One `DdsContext` is one ROS node: a DomainParticipant (USER_DATA `enclave=/;`), publishers and
subscriptions on `rt/<fully qualified name>` with the types `pkg::msg::dds_::Name_`, QoS mapped as
rmw does, and a `ros_discovery_info` writer so that `ros2 node list` shows the node.

Messages are encoded with rosbags and written as raw CDR, and read the same way; the cyclonedds
`IdlStruct` classes only name the DDS types. Unless `CYCLONEDDS_URI` is set, Cyclone is confined
to the loopback interface without multicast (`LOOPBACK_CONFIG`, same as `config/cyclonedds.xml`).

Example:
    with DdsContext('teleop', 'chamber1') as ctx:
        pub = ctx.create_publisher(types.LIGHT_COMMAND, 'light/command')
        pub.publish(types.new(types.LIGHT_COMMAND, mode=0, x=0.4, width=0.1))
"""

from __future__ import annotations

import logging
import os
import time
from typing import Any, Callable

from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
import numpy as np

from growspace_sim.ros import idl, names, qos as ros_qos, types

LOOPBACK_CONFIG = (
    '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    '<AllowMulticast>false</AllowMulticast></General><Discovery>'
    '<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32'
    '</MaxAutoParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers></Discovery>'
    '</Domain></CycloneDDS>')
MAX_DOMAIN_ID = 232  # highest id whose RTPS ports fit in 16 bits with Cyclone's defaults
DISCOVERY_TOPIC = 'ros_discovery_info'
PARTICIPANT_INFO = 'rmw_dds_common/msg/ParticipantEntitiesInfo'
_GID = 'rmw_dds_common/msg/Gid'
_NODE_INFO = 'rmw_dds_common/msg/NodeEntitiesInfo'
_ANY_STATE = SampleState.Any | ViewState.Any | InstanceState.Any
_POLL_S = 0.005  # matching has no blocking wait in the Python binding, so poll at 5 ms

logger = logging.getLogger(__name__)

MessageOrError = Any  # a rosbags message, or the types.CdrError explaining why it is not one


# --- Private cyclonedds API, pinned to cyclonedds==11.0.1 -------------------------------------
# The public DataWriter.write/DataReader.take convert uint8[] to a list of Python ints (5-10x
# slower on images); the C-layer calls move CDR bytes as they are. Entities have no public
# delete, so __del__ (which dds_delete's them once) is called to close deterministically.
from cyclonedds._clayer import ddspy_take, ddspy_write  # noqa: E402,I100


def _write_raw(writer: DataWriter, cdr: bytes) -> None:
    # DataWriter.write pads the payload to a multiple of 4 bytes; do the same.
    ret = ddspy_write(writer._ref, cdr.ljust((len(cdr) + 3) & ~3, b'\0'))
    if ret < 0:
        # Cyclone checks the CDR against the topic type on write: -3 is BAD_PARAMETER.
        raise DdsError(f'dds_write failed with {ret} on {writer.topic.name} '
                       f'(is it a valid XCDR1 {writer.topic.typename}?)')


def _take_raw(reader: DataReader, max_n: int) -> list[bytes]:
    ret = ddspy_take(reader._ref, _ANY_STATE, max_n)
    if isinstance(ret, int):
        raise DdsError(f'dds_take failed with {ret} on {reader.topic.name}')
    return [data for data, info in ret if info.valid_data]


def _delete_entity(entity: Any) -> None:
    entity.__del__()
# ----------------------------------------------------------------------------------------------


class DdsError(RuntimeError):
    """Raised when Cyclone DDS reports an error code."""


def ensure_loopback_config() -> str:
    """Confine Cyclone DDS to loopback without multicast unless the user configured it.

    Must run before the first participant of the process is created.

    Returns:
        The effective CYCLONEDDS_URI.
    """
    if not os.environ.get('CYCLONEDDS_URI'):
        os.environ['CYCLONEDDS_URI'] = LOOPBACK_CONFIG
    return os.environ['CYCLONEDDS_URI']


def domain_id_from_env() -> int:
    """Read ROS_DOMAIN_ID as ROS does (unset or empty means 0).

    Returns:
        The domain id.

    Raises:
        ValueError: ROS_DOMAIN_ID is not an integer in [0, 232].
    """
    text = os.environ.get('ROS_DOMAIN_ID', '').strip()
    if not text:
        return 0
    try:
        value = int(text)
    except ValueError as e:
        raise ValueError(f'ROS_DOMAIN_ID ({text!r}) must be an integer') from e
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise ValueError(f'ROS_DOMAIN_ID ({value}) must be in [0, {MAX_DOMAIN_ID}]')
    return value


def _wait_until(predicate: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            return False
        time.sleep(_POLL_S)
    return True


class Publisher:
    """A ROS publisher: typed messages or ready-made CDR bytes onto one DDS topic."""

    def __init__(self, writer: DataWriter, typename: str, topic: str,
                 profile: ros_qos.QosProfile) -> None:
        """Wrap a DataWriter; use `DdsContext.create_publisher` instead.

        Args:
            writer: The DataWriter on the DDS topic.
            typename: ROS type name of the messages.
            topic: Fully qualified ROS topic name.
            profile: The QoS profile the writer was created with.
        """
        self.writer = writer
        self.typename = typename
        self.topic = topic
        self.qos = profile

    @property
    def gid(self) -> bytes:
        """The writer's 16-byte DDS GUID, which ROS uses as its gid."""
        return self.writer.guid.bytes

    def publish(self, msg: Any) -> bytes:
        """Serialise and publish a message.

        Args:
            msg: A rosbags message of this publisher's type (e.g. from `types.new()`).

        Returns:
            The CDR bytes written (encapsulation header included, unpadded), for a recorder.
        """
        return self.publish_raw(types.serialize(msg, self.typename))

    def publish_raw(self, cdr: bytes) -> bytes:
        """Publish CDR bytes as they are (XCDR1 with the 4-byte encapsulation header).

        Cyclone DDS itself rejects bytes that do not fit the type's layout (truncated, bad
        lengths); what it lets through but rosbags cannot decode (invalid UTF-8, trailing
        garbage) reaches subscribers, whose `take` reports it as an error.

        Args:
            cdr: The serialised message.

        Returns:
            `cdr`, for a recorder.

        Raises:
            DdsError: The write failed.
        """
        _write_raw(self.writer, cdr)
        return cdr

    def matched_count(self) -> int:
        """Return the number of subscriptions (local or remote) matched with this publisher."""
        return len(self.writer.get_matched_subscriptions())

    def wait_for_acks(self, timeout: float = 5.0) -> bool:
        """Wait until every matched reliable subscription acknowledged all published samples.

        Args:
            timeout: Maximum wait [s].

        Returns:
            True if all samples were acknowledged in time.
        """
        return self.writer.wait_for_acks(int(timeout * 1e9))

    def wait_for_subscribers(self, count: int = 1, timeout: float = 5.0) -> bool:
        """Wait until at least `count` subscriptions are matched.

        Args:
            count: Number of subscriptions to wait for.
            timeout: Maximum wait [s].

        Returns:
            True if matched in time.
        """
        return _wait_until(lambda: self.matched_count() >= count, timeout)


class Subscription:
    """A ROS subscription: takes CDR bytes from one DDS topic and decodes them."""

    def __init__(self, reader: DataReader, typename: str, topic: str,
                 profile: ros_qos.QosProfile, callback: Callable[[Any], None] | None) -> None:
        """Wrap a DataReader; use `DdsContext.create_subscription` instead.

        Args:
            reader: The DataReader on the DDS topic.
            typename: ROS type name of the messages.
            topic: Fully qualified ROS topic name.
            profile: The QoS profile the reader was created with.
            callback: Called with each good message by `DdsContext.spin_once`, or None.
        """
        self.reader = reader
        self.typename = typename
        self.topic = topic
        self.qos = profile
        self.callback = callback
        self.condition = ReadCondition(reader, _ANY_STATE)
        self._waitset = WaitSet(reader.participant)
        self._waitset.attach(self.condition)

    @property
    def gid(self) -> bytes:
        """The reader's 16-byte DDS GUID, which ROS uses as its gid."""
        return self.reader.guid.bytes

    def take(self, max_n: int = 64) -> list[tuple[bytes, MessageOrError]]:
        """Take up to `max_n` received samples without blocking.

        Malformed samples do not raise: they come back with a `types.CdrError` in place of the
        message, so the caller can log and drop them.

        Args:
            max_n: Maximum number of samples.

        Returns:
            (CDR bytes as received, message or CdrError) per sample, oldest first.
        """
        out = []
        for data in _take_raw(self.reader, max_n):
            try:
                out.append((data, types.deserialize(data, self.typename)))
            except types.CdrError as e:
                out.append((data, e))
        return out

    def wait(self, timeout: float) -> bool:
        """Block until a sample is available or the timeout passes.

        Args:
            timeout: Maximum wait [s].

        Returns:
            True if a sample is available.
        """
        return self._waitset.wait(max(0, int(timeout * 1e9))) > 0

    def matched_count(self) -> int:
        """Return the number of publishers (local or remote) matched with this subscription."""
        return len(self.reader.get_matched_publications())

    def wait_for_publishers(self, count: int = 1, timeout: float = 5.0) -> bool:
        """Wait until at least `count` publishers are matched.

        Args:
            count: Number of publishers to wait for.
            timeout: Maximum wait [s].

        Returns:
            True if matched in time.
        """
        return _wait_until(lambda: self.matched_count() >= count, timeout)


class DdsContext:
    """One ROS node on Cyclone DDS: participant, endpoints and its ros_discovery_info entry."""

    def __init__(self, node_name: str, namespace: str = '/', domain_id: int | None = None) -> None:
        """Create the participant and announce the (still empty) node.

        Args:
            node_name: ROS node name, e.g. `growspace_sim`.
            namespace: ROS namespace, e.g. `/chamber1`; relative ones are made absolute.
            domain_id: DDS domain; ROS_DOMAIN_ID (default 0) when None.

        Raises:
            names.InvalidNameError: The node name or namespace is invalid.
            ValueError: The domain id is out of range.
        """
        names.validate_node_name(node_name)
        self.node_name = node_name
        self.namespace = names.normalize_namespace(namespace)
        self.domain_id = domain_id_from_env() if domain_id is None else domain_id
        if not 0 <= self.domain_id <= MAX_DOMAIN_ID:
            raise ValueError(f'domain_id ({self.domain_id}) must be in [0, {MAX_DOMAIN_ID}]')
        ensure_loopback_config()
        # rmw only adds remote participants carrying an enclave to its graph.
        self.participant = DomainParticipant(
            self.domain_id, qos=Qos(Policy.Userdata(data=b'enclave=/;')))
        self._topics: dict[str, Topic] = {}
        self._publishers: list[Publisher] = []
        self._subscriptions: list[Subscription] = []
        self._spin_waitset = WaitSet(self.participant)
        self._spin_conditions: list[ReadCondition] = []
        self._closed = False
        self._discovery = self._create_publisher(
            PARTICIPANT_INFO, DISCOVERY_TOPIC, ros_qos.DISCOVERY_INFO_WRITER)
        self._announce()

    @property
    def gid(self) -> bytes:
        """The participant's 16-byte DDS GUID."""
        return self.participant.guid.bytes

    def resolve(self, topic: str) -> str:
        """Expand a topic name for this node (relative, `~/` private, absolute).

        Args:
            topic: The ROS topic name.

        Returns:
            The fully qualified name.
        """
        return names.resolve_topic(topic, self.node_name, self.namespace)

    def _dds_topic(self, typename: str, topic: str, profile: ros_qos.QosProfile
                   ) -> tuple[str, Topic]:
        if self._closed:
            raise DdsError(f'Node {self.node_name!r} is closed')
        if profile.avoid_ros_namespace_conventions:
            fq_name, dds_name = topic, topic
        else:
            fq_name = self.resolve(topic)
            dds_name = names.dds_topic(fq_name)
        dds_topic = self._topics.get(dds_name)
        if dds_topic is None:
            dds_topic = Topic(self.participant, dds_name, idl.idl_class(typename))
            self._topics[dds_name] = dds_topic
        elif dds_topic.typename != types.dds_type_name(typename):
            raise ValueError(f'Topic {fq_name!r} already has type {dds_topic.typename}, '
                             f'not {types.dds_type_name(typename)}')
        return fq_name, dds_topic

    def _create_publisher(self, typename: str, topic: str,
                          profile: ros_qos.QosProfile) -> Publisher:
        fq_name, dds_topic = self._dds_topic(typename, topic, profile)
        writer = DataWriter(self.participant, dds_topic,
                            qos=ros_qos.to_dds(profile, types.type_hash(typename)))
        return Publisher(writer, typename, fq_name, profile)

    def create_publisher(self, typename: str, topic: str,
                         qos: ros_qos.QosProfile = ros_qos.DEFAULT) -> Publisher:
        """Create a publisher, as rclpy's `Node.create_publisher`.

        Args:
            typename: ROS type name, e.g. `growspace_msgs/msg/LightCommand`.
            topic: ROS topic name, resolved in this node's namespace.
            qos: QoS profile.

        Returns:
            The publisher.

        Raises:
            names.InvalidNameError: The topic name is invalid.
            KeyError: The type is unknown.
            ValueError: The DDS topic exists with another type.
        """
        publisher = self._create_publisher(typename, topic, qos)
        self._publishers.append(publisher)
        self._announce()
        return publisher

    def create_subscription(self, typename: str, topic: str,
                            qos: ros_qos.QosProfile = ros_qos.DEFAULT,
                            callback: Callable[[Any], None] | None = None) -> Subscription:
        """Create a subscription, as rclpy's `Node.create_subscription`.

        With a callback, `spin_once` delivers the messages; without one, call `take`.

        Args:
            typename: ROS type name.
            topic: ROS topic name, resolved in this node's namespace.
            qos: QoS profile.
            callback: Called with each well-formed message by `spin_once`.

        Returns:
            The subscription.

        Raises:
            names.InvalidNameError: The topic name is invalid.
            KeyError: The type is unknown.
            ValueError: The DDS topic exists with another type.
        """
        fq_name, dds_topic = self._dds_topic(typename, topic, qos)
        reader = DataReader(self.participant, dds_topic,
                            qos=ros_qos.to_dds(qos, types.type_hash(typename)))
        subscription = Subscription(reader, typename, fq_name, qos, callback)
        self._subscriptions.append(subscription)
        if callback is not None:
            self._spin_conditions.append(ReadCondition(reader, _ANY_STATE))
            self._spin_waitset.attach(self._spin_conditions[-1])
        self._announce()
        return subscription

    def spin_once(self, timeout: float = 0.1) -> int:
        """Wait for data on subscriptions with callbacks, then run the callbacks.

        Malformed samples are logged and dropped. Exceptions from callbacks propagate.

        Args:
            timeout: Maximum wait for the first sample [s].

        Returns:
            The number of callbacks run.
        """
        if self._closed:
            raise DdsError(f'Node {self.node_name!r} is closed')
        self._spin_waitset.wait(max(0, int(timeout * 1e9)))
        done = 0
        for subscription in self._subscriptions:
            if subscription.callback is None:
                continue
            for data, msg in subscription.take():
                if isinstance(msg, types.CdrError):
                    logger.warning('Dropped a malformed sample on %s: %s', subscription.topic, msg)
                    continue
                subscription.callback(msg)
                done += 1
        return done

    def _snapshot(self, with_node: bool = True) -> Any:
        def gid(raw: bytes) -> Any:
            return types.new(_GID, data=np.frombuffer(raw, dtype=np.uint8))

        nodes = [types.new(
            _NODE_INFO, node_namespace=self.namespace, node_name=self.node_name,
            reader_gid_seq=[gid(s.gid) for s in self._subscriptions],
            writer_gid_seq=[gid(p.gid) for p in self._publishers])] if with_node else []
        return types.new(PARTICIPANT_INFO, gid=gid(self.gid), node_entities_info_seq=nodes)

    def _announce(self, with_node: bool = True) -> None:
        # rmw republishes the whole snapshot of its participant whenever an entity changes.
        self._discovery.publish(self._snapshot(with_node))

    def close(self) -> None:
        """Withdraw the node from the ROS graph and delete all DDS entities. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._announce(with_node=False)
            # Let readers of ros_discovery_info see the empty node list before the writer goes.
            self._discovery.writer.wait_for_acks(int(0.2e9))
        except Exception as e:  # noqa: BLE001 - closing must go on
            logger.warning('Could not announce the end of node %s: %s', self.node_name, e)
        # Children before parents, so no Python object is left holding a deleted handle.
        entities = [self._spin_waitset, *self._spin_conditions]
        for s in self._subscriptions:
            entities += [s._waitset, s.condition, s.reader]
        entities += [p.writer for p in (*self._publishers, self._discovery)]
        entities += [*self._topics.values(), self.participant]
        for entity in entities:
            _delete_entity(entity)
        self._publishers.clear()
        self._subscriptions.clear()
        self._spin_conditions.clear()
        self._topics.clear()

    def __enter__(self) -> DdsContext:
        """Return self; `close()` runs on exit."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the context."""
        self.close()
