"""rcl name resolution and the rmw QoS mapping, without starting DDS."""

from __future__ import annotations

from cyclonedds.qos import Policy
import pytest
from rosbags.rosbag2.metadata import parse_qos, QosHistory, QosReliability

from growspace_sim.ros import names, qos, types


@pytest.mark.parametrize(('name', 'node', 'ns', 'expected'), [
    ('plant/state', 'sim', '/chamber1', '/chamber1/plant/state'),
    ('plant/state', 'sim', 'chamber1', '/chamber1/plant/state'),
    ('plant/state', 'sim', '', '/plant/state'),
    ('/clock', 'sim', '/chamber1', '/clock'),
    ('~/debug', 'sim', '/lab/c2', '/lab/c2/sim/debug'),
    ('~', 'sim', '/', '/sim'),
    ('{node}/x', 'sim', '/c', '/c/sim/x'),
    ('{ns}/x', 'sim', '/', '/x'),
])
def test_resolve_topic(name: str, node: str, ns: str, expected: str) -> None:
    assert names.resolve_topic(name, node, ns) == expected


@pytest.mark.parametrize(('name', 'node', 'ns', 'match'), [
    ('', 'sim', '/', 'must not be empty'),
    ('a//b', 'sim', '/', '//'),
    ('a/', 'sim', '/', 'end with'),
    ('1abc', 'sim', '/', 'starts with a digit'),
    ('a-b', 'sim', '/', "contains '-'"),
    ('a~b', 'sim', '/', '~'),
    ('~x', 'sim', '/', '~'),
    ('{bogus}/x', 'sim', '/', 'unknown substitution'),
    ('x', 'my-node', '/', 'Node name'),
    ('x', '', '/', 'Node name must not be empty'),
    ('x', 'sim', '/ns/', 'Namespace'),
    ('x', 'sim', '/9ns', 'Namespace'),
])
def test_invalid_names(name: str, node: str, ns: str, match: str) -> None:
    with pytest.raises(names.InvalidNameError, match=match):
        names.resolve_topic(name, node, ns)


def test_dds_topic_prefixes() -> None:
    assert names.dds_topic('/chamber1/light/command') == 'rt/chamber1/light/command'
    assert names.dds_topic('/gs/reset', names.REQUEST_PREFIX, 'Request') == 'rq/gs/resetRequest'
    assert names.dds_topic('/gs/reset', names.REPLY_PREFIX, 'Reply') == 'rr/gs/resetReply'
    with pytest.raises(names.InvalidNameError, match='fully qualified'):
        names.dds_topic('relative/name')


def test_default_profile_maps_like_rmw_cyclonedds() -> None:
    typehash = types.type_hash(types.STEP_RESULT)
    dds_qos = qos.to_dds(qos.DEFAULT, typehash)
    assert dds_qos[Policy.History] == Policy.History.KeepLast(10)
    assert dds_qos[Policy.Reliability] == Policy.Reliability.Reliable(
        max_blocking_time=2**63 - 1)
    assert dds_qos[Policy.Durability] == Policy.Durability.Volatile
    assert dds_qos[Policy.WriterDataLifecycle] == Policy.WriterDataLifecycle(autodispose=False)
    assert dds_qos[Policy.DataRepresentation] == Policy.DataRepresentation(
        use_cdrv0_representation=True)
    assert dds_qos[Policy.Liveliness] == Policy.Liveliness.Automatic(lease_duration=2**63 - 1)
    assert dds_qos[Policy.Userdata].data == f'typehash={typehash};'.encode()
    assert Policy.Deadline not in dds_qos and Policy.Lifespan not in dds_qos


def test_sensor_latched_and_discovery_profiles() -> None:
    sensor = qos.to_dds(qos.SENSOR_DATA)
    assert sensor[Policy.Reliability] == Policy.Reliability.BestEffort
    assert sensor[Policy.History] == Policy.History.KeepLast(5)
    assert Policy.Userdata not in sensor
    latched = qos.to_dds(qos.LATCHED)
    assert latched[Policy.Durability] == Policy.Durability.TransientLocal
    assert latched[Policy.DurabilityService].history == Policy.History.KeepLast(1)
    reader = qos.to_dds(qos.DISCOVERY_INFO_READER)
    assert reader[Policy.History] == Policy.History.KeepAll
    assert qos.DISCOVERY_INFO_WRITER.avoid_ros_namespace_conventions
    timed = qos.to_dds(qos.QosProfile(deadline_ns=5, lifespan_ns=7,
                                      liveliness_lease_duration_ns=9))
    assert timed[Policy.Deadline].deadline == 5 and timed[Policy.Lifespan].lifespan == 7
    assert timed[Policy.Liveliness] == Policy.Liveliness.Automatic(lease_duration=9)


@pytest.mark.parametrize(('field', 'value', 'match'), [
    ('history', 'keep_some', 'history'),
    ('depth', 0, 'depth'),
    ('reliability', 'sometimes', 'reliability'),
    ('durability', 'forever', 'durability'),
    ('deadline_ns', -1, 'deadline_ns'),
])
def test_invalid_profiles(field: str, value: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        qos.QosProfile(**{field: value})


def test_offered_qos_yaml_is_rosbag2_v9() -> None:
    text = qos.offered_qos_yaml([qos.DEFAULT, qos.SENSOR_DATA.with_depth(3)])
    parsed = parse_qos(text)
    assert [p.history for p in parsed] == [QosHistory.KEEP_LAST] * 2
    assert [p.depth for p in parsed] == [10, 3]
    assert [p.reliability for p in parsed] == [QosReliability.RELIABLE,
                                               QosReliability.BEST_EFFORT]
    assert parsed[0].deadline.sec == 9223372036 and parsed[0].deadline.nsec == 854775807
    assert 'history: keep_last' in text and 'history: 1' not in text  # v9 strings, not v8 ints
    assert qos.offered_qos_yaml([]) == '[]'
