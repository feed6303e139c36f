"""Reading a GrowSpace recording: an MCAP file with the ROS 2 profile, messages in file order."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
import dataclasses
import os
from pathlib import Path
from typing import Any

from mcap.records import Message

from growspace_sim.recording import PROFILE
from growspace_sim.recording.scan import (
    Damage, damage_from_metadata, McapScan, RECOVERY_METADATA)
from growspace_sim.recording.splits import split_files
from growspace_sim.ros import qos as ros_qos, types
from growspace_sim.ros.interface import TOPICS


class ReplayError(Exception):
    """Raised when a recording cannot be read or does not hold what the request needs."""


# ---------------------------------------------------------------------- reading
@dataclasses.dataclass(frozen=True)
class BagMessage:
    """One recorded message, still serialised."""

    topic: str
    typename: str
    log_time: int  # ns
    publish_time: int  # ns
    data: bytes  # CDR with encapsulation header

    def decode(self) -> Any:
        return types.deserialize(self.data, self.typename)


@dataclasses.dataclass(frozen=True)
class TopicInfo:
    topic: str
    typename: str
    qos: ros_qos.QosProfile
    type_hash: str
    count: int


class Bag:
    """A finished MCAP recording opened for reading (see ``recording.recover`` for broken ones).

    A chunk that cannot be read (CRC mismatch, decompression error, bad record) does not stop
    the reading: ``messages`` skips it, adds it to ``damage`` and calls ``on_damage``.

    A split recording (a directory of ``NAME_<i>.mcap`` files, ``recording.SplitRecorder``) reads
    as one: its files' messages in file order, one after the other; topics and message counts
    over all files; each metadata record as the first file holds it (the run's start).

    Args:
        path: The ``.mcap`` file, or a split recording's directory.
        on_damage: Called with each unreadable part of the file as reading meets it.

    Raises:
        ReplayError: The file does not exist, is not MCAP, is not profile ``ros2``, or has no
            summary (cut short by a crash: the message says how to recover it).
    """

    def __init__(self, path: str | os.PathLike,
                 on_damage: Callable[[Damage], None] | None = None) -> None:
        from mcap.reader import SeekingReader

        self.path = Path(path)
        self.on_damage = on_damage
        self.damage: list[Damage] = []  # what reading has skipped so far
        self._parts: list[Bag] = []
        if not self.path.exists():
            raise ReplayError(f'No recording at {self.path}: the file does not exist.')
        if self.path.is_dir():
            self._open_split()
            return
        try:
            self._stream = open(self.path, 'rb')
        except OSError as e:
            raise ReplayError(f'Cannot open {self.path}: {e.strerror or e}') from e
        try:
            self._reader = SeekingReader(self._stream, validate_crcs=True)
            header = self._reader.get_header()
        except Exception as e:  # noqa: BLE001 - InvalidMagic, EndOfFile, struct errors
            self.close()
            raise ReplayError(f'{self.path} is not an MCAP file ({type(e).__name__}).') from e
        if header.profile != PROFILE:
            self.close()
            raise ReplayError(f'{self.path} has MCAP profile {header.profile!r}, expected '
                              f'{PROFILE!r} (a ROS 2 recording).')
        try:
            summary = self._reader.get_summary()
            if summary is None:
                raise ValueError('no summary section')
        except Exception as e:  # noqa: BLE001 - truncated footer or summary
            self.close()
            raise ReplayError(
                f'{self.path} is incomplete ({e or type(e).__name__}): the recording was cut '
                f'short, e.g. by a hard kill. Copy its complete chunks into a new file with '
                f'`growspace-replay recover {self.path} FIXED.mcap`.') from e
        self.summary = summary
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        self.topics: dict[str, TopicInfo] = {}
        self._channels: dict[int, TopicInfo] = {}
        for cid, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            if schema is None or channel.message_encoding != 'cdr':
                continue
            info = TopicInfo(channel.topic, schema.name,
                             parse_qos(channel.metadata.get('offered_qos_profiles', '')),
                             channel.metadata.get('topic_type_hash', ''), counts.get(cid, 0))
            self._channels[cid] = info
            self.topics[channel.topic] = info
        try:
            self.metadata = {m.name: dict(m.metadata) for m in self._reader.iter_metadata()}
        except Exception as e:  # noqa: BLE001 - metadata records carry no CRC of their own
            self.metadata = {}
            self._lost([Damage(0, 0, 'metadata', f'unreadable metadata record: {e!r}')])
        if RECOVERY_METADATA in self.metadata:  # the holes of a recovered file
            try:
                self._lost(damage_from_metadata(self.metadata[RECOVERY_METADATA]))
            except ValueError as e:
                self._lost([Damage(0, 0, 'metadata', str(e))])

    def _open_split(self) -> None:
        """Open every file of a split recording (``path`` is its directory)."""
        files = split_files(self.path)
        if not files:
            raise ReplayError(f'{self.path} is a directory without recording files '
                              f'({self.path.name}_0.mcap, ...); give a .mcap file or a split '
                              f'recording.')
        forward = self._lost
        try:
            for file in files:  # damage is named with its file: offsets are per file
                self._parts.append(Bag(file, on_damage=lambda part, name=file.name: forward(
                    [dataclasses.replace(part, what=f'{part.what} of {name}')])))
        except ReplayError as e:
            self.close()
            incomplete = 'incomplete' in str(e)
            raise ReplayError(
                f'{e}' + (f' In a split recording, `growspace-replay recover {self.path}` '
                          f'repairs its last file in place.' if incomplete else '')) from e
        self.summary = None
        self.topics = {}
        for part in self._parts:
            for topic, info in part.topics.items():
                known = self.topics.get(topic)
                self.topics[topic] = info if known is None else dataclasses.replace(
                    known, count=known.count + info.count)
        self.metadata = {}
        for part in self._parts:
            for name, data in part.metadata.items():
                self.metadata.setdefault(name, data)

    @property
    def files(self) -> list[Path]:
        """The recording's files (one, or a split recording's in order)."""
        return [part.path for part in self._parts] if self._parts else [self.path]

    @property
    def size_bytes(self) -> int:
        """Bytes on disk over all its files."""
        return sum(f.stat().st_size for f in self.files)

    @property
    def start_time(self) -> int:
        if self._parts:
            return min((p.start_time for p in self._parts if p.end_time), default=0)
        return self.summary.statistics.message_start_time if self.summary.statistics else 0

    @property
    def end_time(self) -> int:
        if self._parts:
            return max((p.end_time for p in self._parts), default=0)
        return self.summary.statistics.message_end_time if self.summary.statistics else 0

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
        """Messages in file order (the order they were recorded in), unreadable chunks skipped.

        Args:
            topics: Only these topics; None = all.
        """
        if self._parts:
            for part in self._parts:
                yield from part.messages(topics)
            return
        wanted = None if topics is None else set(topics)
        scan = McapScan(self._stream, self.summary.chunk_indexes)
        reported = 0
        for record in scan.records():
            if len(scan.damage) > reported:
                self._lost(scan.damage[reported:])
                reported = len(scan.damage)
            if not isinstance(record, Message):
                continue
            info = self._channels.get(record.channel_id)
            if info is None or (wanted is not None and info.topic not in wanted):
                continue
            yield BagMessage(info.topic, info.typename, record.log_time,
                             record.publish_time, record.data)
        self._lost(scan.damage[reported:])

    def _lost(self, damage: list[Damage]) -> None:
        for part in damage:
            if part in self.damage:  # a second pass over the file meets the same damage
                continue
            self.damage.append(part)
            if self.on_damage is not None:
                self.on_damage(part)

    def chamber_topics(self, namespace: str | None = None) -> dict[str, str]:
        """Map the node's relative topic names to the recorded ones.

        Args:
            namespace: The chamber namespace; None = the only chamber in the file.

        Returns:
            Relative name (``step_result``) -> recorded name (``/growspace/step_result``).

        Raises:
            ReplayError: No chamber, or several and no namespace given.
        """
        candidates = sorted(t[:-len('/step_result')] or '/' for t, i in self.topics.items()
                            if t.endswith('/step_result') and i.typename == types.STEP_RESULT)
        if namespace is not None:
            namespace = '/' + namespace.strip('/') if namespace.strip('/') else '/'
            if namespace not in candidates:
                raise ReplayError(f'{self.path} has no chamber in namespace {namespace!r}; '
                                  f'found {candidates or "none"}.')
        elif len(candidates) == 1:
            namespace = candidates[0]
        elif not candidates:
            raise ReplayError(f'{self.path} holds no {types.STEP_RESULT} topic: not a GrowSpace '
                              f'chamber recording.')
        else:
            raise ReplayError(f'{self.path} holds several chambers {candidates}; pick one with '
                              f'--namespace.')
        prefix = '' if namespace == '/' else namespace
        out = {}
        for topic in TOPICS:
            rel = topic.name
            full = rel if rel.startswith('/') else f'{prefix}/{rel}'
            if full in self.topics:
                out[rel] = full
        return out

    def close(self) -> None:
        for part in self._parts:
            part.close()
        stream = getattr(self, '_stream', None)
        if stream is not None:
            stream.close()

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def parse_qos(text: str) -> ros_qos.QosProfile:
    """The first profile of an ``offered_qos_profiles`` YAML string (rosbag2 v8 or v9).

    rosbags parses it (``rosbags.rosbag2.metadata.parse_qos``); unknown or missing values fall
    back to the ROS default profile.
    """
    from rosbags.rosbag2.errors import ReaderError
    from rosbags.rosbag2.metadata import parse_qos as rosbags_parse_qos

    try:
        profiles = rosbags_parse_qos(text)
    except (ReaderError, KeyError, TypeError, ValueError):
        return ros_qos.DEFAULT
    if not profiles:
        return ros_qos.DEFAULT
    qos = profiles[0]
    fields: dict[str, Any] = {}
    for key, value in (('history', qos.history), ('reliability', qos.reliability),
                       ('durability', qos.durability), ('liveliness', qos.liveliness)):
        name = value.name.lower()
        if name not in ('unknown', 'system_default', 'best_available'):
            fields[key] = name
    if isinstance(qos.depth, int) and qos.depth > 0:
        fields['depth'] = qos.depth
    try:
        return ros_qos.QosProfile(**fields)
    except ValueError:
        return ros_qos.DEFAULT
