"""rmw QoS profiles and their Cyclone DDS form, mapped the way rmw_cyclonedds_cpp does it.

Jazzy `rmw_cyclonedds_cpp` (`create_readwrite_qos` in rmw_node.cpp) turns a ROS profile into
DDS QoS as follows; `to_dds()` repeats it so a ROS node matches and shows our endpoints as its own:
reliable writers block forever (`max_blocking_time` infinite), transient-local also sets the
durability service history, autodispose is off, liveliness is automatic with an infinite lease
unless set, deadline and lifespan are only set when given, the data representation is XCDR1 only
and USER_DATA carries `typehash=RIHS01_...;`.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

_HISTORIES = ('keep_last', 'keep_all')
_RELIABILITIES = ('reliable', 'best_effort')
_DURABILITIES = ('volatile', 'transient_local')
_LIVELINESSES = ('automatic', 'manual_by_topic')
# rmw's RMW_DURATION_INFINITE {9223372036 s, 854775807 ns}: what a ROS tool reports for an
# unset deadline, lifespan or lease when it reads the QoS back from DDS discovery.
_INFINITE_SEC = 9223372036
_INFINITE_NSEC = 854775807


@dataclasses.dataclass(frozen=True)
class QosProfile:
    """A ROS 2 QoS profile (the fields of rmw_qos_profile_t that rmw maps to DDS).

    Durations are in nanoseconds; 0 means unspecified, which rmw maps to infinite.
    """

    history: str = 'keep_last'  # keep_last | keep_all
    depth: int = 10  # samples kept per writer/reader with keep_last [1]
    reliability: str = 'reliable'  # reliable | best_effort
    durability: str = 'volatile'  # volatile | transient_local
    deadline_ns: int = 0  # expected maximum period between samples [ns], 0 = unspecified
    lifespan_ns: int = 0  # age after which a sample is dropped [ns], 0 = unspecified
    liveliness: str = 'automatic'  # automatic | manual_by_topic
    liveliness_lease_duration_ns: int = 0  # [ns], 0 = unspecified
    avoid_ros_namespace_conventions: bool = False  # true: no rt/ prefix on the DDS topic

    def __post_init__(self) -> None:
        """Validate every field.

        Raises:
            ValueError: A field has a value rmw would reject.
        """
        for name, allowed in (('history', _HISTORIES), ('reliability', _RELIABILITIES),
                              ('durability', _DURABILITIES), ('liveliness', _LIVELINESSES)):
            if getattr(self, name) not in allowed:
                raise ValueError(f'QoS {name} ({getattr(self, name)!r}) must be one of {allowed}')
        if self.history == 'keep_last' and not 1 <= self.depth <= 2**31 - 1:
            raise ValueError(f'QoS depth ({self.depth}) must be in [1, 2**31 - 1] for keep_last')
        for name in ('deadline_ns', 'lifespan_ns', 'liveliness_lease_duration_ns'):
            if getattr(self, name) < 0:
                raise ValueError(f'QoS {name} ({getattr(self, name)}) must not be negative')

    def with_depth(self, depth: int) -> QosProfile:
        """Return a copy with another keep_last depth (like rclpy's `create_publisher(T, n, d)`).

        Args:
            depth: The new depth.

        Returns:
            The new profile.
        """
        return dataclasses.replace(self, depth=depth)


# rmw/qos_profiles.h: rmw_qos_profile_default, what `create_publisher(T, name, 10)` gets.
DEFAULT = QosProfile()
# rmw_qos_profile_sensor_data.
SENSOR_DATA = QosProfile(depth=5, reliability='best_effort')
# A latched topic: late joiners get the last sample (rclpy's transient-local idiom).
LATCHED = QosProfile(depth=1, durability='transient_local')
# rmw_qos_profile_services_default.
SERVICES_DEFAULT = QosProfile()
# /clock, per the interop design: reliable keeps best-effort subscribers compatible.
CLOCK = QosProfile(depth=1)
# ros_discovery_info as rmw_cyclonedds creates it: raw DDS name, writer keeps the last snapshot.
DISCOVERY_INFO_WRITER = QosProfile(depth=1, durability='transient_local',
                                   avoid_ros_namespace_conventions=True)
DISCOVERY_INFO_READER = QosProfile(history='keep_all', depth=1, durability='transient_local',
                                   avoid_ros_namespace_conventions=True)


def user_data(typehash: str | None, extra: str = '') -> bytes:
    """Build endpoint USER_DATA as rmw does: `<extra>typehash=RIHS01_<hex>;`.

    Args:
        typehash: The RIHS01 hash, or None to leave it out (rmw then records a zero hash).
        extra: Text put before the hash, e.g. `serviceid=...;` for service endpoints.

    Returns:
        The USER_DATA bytes.
    """
    return (extra + (f'typehash={typehash};' if typehash else '')).encode('ascii')


def to_dds(profile: QosProfile, typehash: str | None = None, extra_user_data: str = ''):
    """Map a profile to Cyclone DDS QoS the way rmw_cyclonedds_cpp does.

    Args:
        profile: The ROS profile.
        typehash: RIHS01 hash of the endpoint's type, put in USER_DATA.
        extra_user_data: Text put before the hash in USER_DATA.

    Returns:
        A `cyclonedds.qos.Qos`.
    """
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.util import duration

    infinite = duration(infinite=True)
    if profile.history == 'keep_all':
        history = Policy.History.KeepAll
    else:
        history = Policy.History.KeepLast(profile.depth)
    policies = [
        history,
        Policy.Reliability.Reliable(max_blocking_time=infinite)
        if profile.reliability == 'reliable' else Policy.Reliability.BestEffort,
        Policy.WriterDataLifecycle(autodispose=False),
        # rmw_cyclonedds and rmw_fastrtps both speak XCDR1 only; a ROS reader rejects XCDR2.
        Policy.DataRepresentation(use_cdrv0_representation=True),
    ]
    if profile.durability == 'transient_local':
        policies += [
            Policy.Durability.TransientLocal,
            Policy.DurabilityService(cleanup_delay=0, history=history, max_samples=-1,
                                     max_instances=-1, max_samples_per_instance=-1),
        ]
    else:
        policies.append(Policy.Durability.Volatile)
    if profile.deadline_ns:
        policies.append(Policy.Deadline(deadline=profile.deadline_ns))
    if profile.lifespan_ns:
        policies.append(Policy.Lifespan(lifespan=profile.lifespan_ns))
    lease = profile.liveliness_lease_duration_ns or infinite
    policies.append(Policy.Liveliness.ManualByTopic(lease_duration=lease)
                    if profile.liveliness == 'manual_by_topic'
                    else Policy.Liveliness.Automatic(lease_duration=lease))
    data = user_data(typehash, extra_user_data)
    if data:
        policies.append(Policy.Userdata(data=data))
    return Qos(*policies)


def _yaml_duration(key: str, ns: int) -> list[str]:
    sec, nsec = divmod(ns, 1_000_000_000) if ns else (_INFINITE_SEC, _INFINITE_NSEC)
    return [f'  {key}:', f'    sec: {sec}', f'    nsec: {nsec}']


def offered_qos_yaml(profiles: QosProfile | Sequence[QosProfile]) -> str:
    """Write profiles as rosbag2 metadata v9 `offered_qos_profiles` (the MCAP channel metadata).

    Unspecified durations are written as rmw's infinite duration, which is what rosbag2 records
    for a live publisher that left them unset.

    Args:
        profiles: One profile per publisher of the topic.

    Returns:
        A YAML list as a string, in rosbag2's block style.
    """
    if isinstance(profiles, QosProfile):
        profiles = [profiles]
    lines = []
    for p in profiles:
        lines += [
            f'- history: {p.history}',
            f'  depth: {p.depth if p.history == "keep_last" else 0}',
            f'  reliability: {p.reliability}',
            f'  durability: {p.durability}',
            *_yaml_duration('deadline', p.deadline_ns),
            *_yaml_duration('lifespan', p.lifespan_ns),
            f'  liveliness: {p.liveliness}',
            *_yaml_duration('liveliness_lease_duration', p.liveliness_lease_duration_ns),
            f'  avoid_ros_namespace_conventions: {str(p.avoid_ros_namespace_conventions).lower()}',
        ]
    return '\n'.join(lines) if lines else '[]'
