"""ROS 2 QoS profiles as plain data: what the chamber offers, and what its recordings say.

The node's topic table (``ros.interface``) is written with these profiles; the rclpy transport
turns them into ``rclpy.qos.QoSProfile`` (``node.rclpy_transport.to_rclpy_qos``) and the recorder
writes them into each MCAP channel as rosbag2's ``offered_qos_profiles`` YAML, so the in-process
recorder, which has no rclpy, writes the same metadata as a live node.
"""

from __future__ import annotations

from collections.abc import Sequence
import dataclasses
import functools
from typing import Any

import yaml

from growspace_sim.core.schema import Bounds, check, param

# rmw's RMW_DURATION_INFINITE {9223372036 s, 854775807 ns}: what a ROS tool reports for an
# unset deadline, lifespan or lease when it reads the QoS back from DDS discovery.
_INFINITE_SEC = 9223372036
_INFINITE_NSEC = 854775807
_DURATION = Bounds(0, 2**63 - 1, integer=True)  # ns


@dataclasses.dataclass(frozen=True)
class QosProfile:
    """A ROS 2 QoS profile (the fields of rmw_qos_profile_t that rmw maps to DDS).

    Durations are in nanoseconds; 0 means unspecified, which rmw maps to infinite.
    """

    history: str = param('keep_last', 'samples kept', choices=('keep_last', 'keep_all'))
    depth: int = param(10, 'samples kept per writer/reader with keep_last',
                       bounds=Bounds(0, 2**31 - 1, integer=True), rule='at least 1 for keep_last')
    reliability: str = param('reliable', 'delivery', choices=('reliable', 'best_effort'))
    durability: str = param('volatile', 'late joiners', choices=('volatile', 'transient_local'))
    deadline_ns: int = param(0, 'expected maximum period between samples', unit='ns',
                             bounds=_DURATION, rule='0 = unspecified')
    lifespan_ns: int = param(0, 'age after which a sample is dropped', unit='ns',
                             bounds=_DURATION, rule='0 = unspecified')
    liveliness: str = param('automatic', 'liveliness', choices=('automatic', 'manual_by_topic'))
    liveliness_lease_duration_ns: int = param(0, 'liveliness lease', unit='ns',
                                              bounds=_DURATION, rule='0 = unspecified')
    avoid_ros_namespace_conventions: bool = param(False, 'true: no rt/ prefix on the DDS topic')

    def __post_init__(self) -> None:
        """Validate every field.

        Raises:
            ValueError: A field has a value rmw would reject, named with its value.
        """
        try:
            check(self)
            if self.history == 'keep_last' and self.depth < 1:
                raise ValueError(f'depth must be at least 1 for keep_last, got {self.depth}.')
        except ValueError as e:
            raise ValueError(f'QoS {e}') from None

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
# /clock: reliable, so best-effort subscribers match too.
CLOCK = QosProfile(depth=1)


def _duration(ns: int) -> dict[str, int]:
    sec, nsec = divmod(ns, 1_000_000_000) if ns else (_INFINITE_SEC, _INFINITE_NSEC)
    return {'sec': sec, 'nsec': nsec}


def offered_qos_yaml(profiles: QosProfile | Sequence[QosProfile]) -> str:
    """Write profiles as rosbag2 metadata v9 ``offered_qos_profiles`` (the MCAP channel metadata).

    Unspecified durations are written as rmw's infinite duration, which is what rosbag2 records
    for a live publisher that left them unset.

    Args:
        profiles: One profile per publisher of the topic.

    Returns:
        A YAML list as a string, in rosbag2's block style.
    """
    return _offered_qos_yaml((profiles,) if isinstance(profiles, QosProfile) else tuple(profiles))


@functools.lru_cache(maxsize=64)
def _offered_qos_yaml(profiles: tuple[QosProfile, ...]) -> str:
    # Cached: PyYAML takes ~0.3 ms a profile, and every recording registers 8 channels.
    entries: list[dict[str, Any]] = [{
        'history': p.history,
        'depth': p.depth if p.history == 'keep_last' else 0,
        'reliability': p.reliability,
        'durability': p.durability,
        'deadline': _duration(p.deadline_ns),
        'lifespan': _duration(p.lifespan_ns),
        'liveliness': p.liveliness,
        'liveliness_lease_duration': _duration(p.liveliness_lease_duration_ns),
        'avoid_ros_namespace_conventions': p.avoid_ros_namespace_conventions,
    } for p in profiles]
    return yaml.safe_dump(entries, sort_keys=False, default_flow_style=False).rstrip('\n')
