"""A recording split into files by size and duration, the way ``ros2 bag record`` splits one.

rosbag2's ``--max-bag-size`` / ``--max-bag-duration`` make a bag directory ``NAME/`` holding
``NAME_0.mcap``, ``NAME_1.mcap``, ... and a ``metadata.yaml`` that lists them. ``SplitRecorder``
writes the same layout. Each file is a complete recording on its own (every channel and every
metadata record written so far is repeated at its start), closed and fsynced before the next
one opens, so a crash can only damage the open (last) file. A file is closed only between two
``write_many`` calls, and the chamber nodes hand over each step (its command, images, states and
result) in one call: a split never falls inside a step's messages.

Limits, both checked before each batch (0 = none):
- ``max_bytes``: message bytes (CDR, uncompressed) per file; the file on disk is smaller (zstd).
  Counting what was written, not the file's size, makes the split points the same on every run.
- ``max_duration_s``: log time one file spans, from its first message [s] (sim time for
  ``sim_node``, so a run at any speed splits at the same steps; wall time on the rig).

The writing recorder holds a lock on ``NAME/.lock`` (``flock``, freed by the OS however the
process ends), so a second recorder or a ``repair`` never touches a file still being written.

``metadata.yaml`` is rewritten (atomically) whenever a file is closed. After a crash it lags;
readers therefore take the files from the directory itself (``split_files``), as
``ros2 bag reindex`` does. ``repair`` copies the readable part of a damaged last file back under
its name (the damaged original is kept beside it as ``NAME_i.mcap.damaged``), so the directory
reads as one recording again; ``SplitRecorder(..., append=True)`` repairs first, then continues
with the next file.
"""

from __future__ import annotations

from collections.abc import Iterable
import contextlib
import dataclasses
import fcntl
import os
from pathlib import Path
import re
import threading
import time

import yaml

from growspace_sim.recording.recorder import (
    CHUNK_SIZE, FLUSH_PERIOD_S, McapRecorder, RecordingError)
from growspace_sim.ros import qos as ros_qos

METADATA_FILE = 'metadata.yaml'
LOCK_FILE = '.lock'  # held (flock) by the recorder writing the directory; the OS frees it on exit
DAMAGED_SUFFIX = '.damaged'  # the original of a repaired file, kept for a person to look at
_RECOVERING_SUFFIX = '.recovering'


def split_path(directory: str | os.PathLike, index: int) -> Path:
    """The ``index``-th file of a split recording: ``DIR/DIR_<index>.mcap`` (rosbag2's names)."""
    directory = Path(directory)
    return directory / f'{directory.name}_{index}.mcap'


def split_files(directory: str | os.PathLike) -> list[Path]:
    """The files of a split recording in order (by their index, not by name: _10 after _9)."""
    directory = Path(directory)
    pattern = re.compile(rf'{re.escape(directory.name)}_(\d+)\.mcap')
    found = []
    for entry in os.scandir(directory):
        match = pattern.fullmatch(entry.name)
        if match and entry.is_file():
            found.append((int(match.group(1)), Path(entry.path)))
    return [path for _, path in sorted(found)]


def is_split_recording(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a directory a ``SplitRecorder`` wrote (it holds ``NAME_<i>.mcap``)."""
    path = Path(path)
    return path.is_dir() and bool(split_files(path))


def _lock(directory: Path) -> int:
    """Take the directory's writer lock; returns its fd.

    Raises:
        RecordingError: another process holds it (a recorder still writing there).
    """
    fd = os.open(directory / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise RecordingError(f'{directory} is being recorded by another process (it holds '
                             f'{directory / LOCK_FILE}); wait for it to stop.') from None
    return fd


def wait_until_free(directory: str | os.PathLike, timeout_s: float) -> bool:
    """Wait until no recorder writes ``directory`` (e.g. a node finishing its last file after
    its parent died). Returns whether it is free; a missing directory is free."""
    directory = Path(directory)
    deadline = time.monotonic() + timeout_s
    while True:
        if not directory.is_dir():
            return True
        try:
            os.close(_lock(directory))  # closing the fd releases the lock
            return True
        except RecordingError:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.05)  # polling a lock another process holds: no event to wait on


@dataclasses.dataclass
class RepairReport:
    """What ``repair`` did to the last file of a split recording."""

    path: Path | None = None  # the repaired file ('' when nothing needed repair)
    messages: int = 0  # messages kept
    damaged: Path | None = None  # where the damaged original now is
    reason: str = ''  # why it needed repair


def repair(directory: str | os.PathLike) -> RepairReport:
    """Make a split recording readable after a crash: recover its last file if it is damaged.

    Only the last file can be damaged (every earlier one was finished and fsynced before the
    next was opened), so only it is checked. Its complete chunks are copied into a new file
    (``recover``), which then takes its name; the original is renamed ``NAME_i.mcap.damaged``.
    A file too short to hold even the MCAP header is moved aside the same way. Safe to run again
    after a crash in the middle of it.

    Args:
        directory: The split recording.

    Returns:
        What was done (``path`` None: the files were all complete).

    Raises:
        RecordingError: The directory cannot be read or written, or a recorder writes it now.
    """

    directory = Path(directory)
    fd = _lock(directory)  # never "repair" a file a live recorder is writing
    try:
        return _repair(directory)
    finally:
        os.close(fd)


def _repair(directory: Path) -> RepairReport:
    from growspace_sim.recording.recovery import readable_summary, recover

    for leftover in directory.glob(f'*{_RECOVERING_SUFFIX}'):
        # A repair cut short: the damaged original is still in place (renamed last), redo it.
        original = leftover.with_name(leftover.name[:-len(_RECOVERING_SUFFIX)])
        if original.exists():
            leftover.unlink()
        else:
            os.replace(leftover, original)
    files = split_files(directory)
    if not files:
        return RepairReport()
    last = files[-1]
    with open(last, 'rb') as stream:
        if readable_summary(stream) is not None:
            return RepairReport()
    damaged = last.with_name(last.name + DAMAGED_SUFFIX)
    temporary = last.with_name(last.name + _RECOVERING_SUFFIX)
    try:
        report = recover(last, temporary, overwrite=True)
    except RecordingError as e:  # not even an MCAP header: nothing to keep
        with contextlib.suppress(FileNotFoundError):
            temporary.unlink()
        os.replace(last, damaged)
        _fsync_directory(directory)
        return RepairReport(None, 0, damaged, str(e))
    os.replace(last, damaged)
    os.replace(temporary, last)
    _fsync_directory(directory)
    reason = report.reason or 'no summary (the file was not finished)'
    return RepairReport(last, report.messages, damaged, reason)


class SplitRecorder:
    """The ``McapRecorder`` interface over a directory of files split by size and duration.

    Channel ids are the recorder's own and stay valid across files. Thread-safe like
    ``McapRecorder``. A failed file (disk full) stops the recorder as ``McapRecorder`` stops.

    Args:
        directory: The recording directory (``NAME/``, files ``NAME/NAME_<i>.mcap``).
        max_bytes: Message bytes per file (0 = no size limit).
        max_duration_s: Log time per file [s] (0 = no duration limit).
        append: Continue an existing split recording with a new file (after ``repair``);
            False refuses an existing directory, as ``McapRecorder`` refuses an existing file.
        chunk_size: As ``McapRecorder``.
        flush_period_s: As ``McapRecorder``.

    Raises:
        RecordingError: The directory exists (without ``append``), is a file, or cannot be
            created or written; a limit is negative.
    """

    def __init__(self, directory: str | os.PathLike, *, max_bytes: int = 0,
                 max_duration_s: float = 0.0, append: bool = False,
                 chunk_size: int = CHUNK_SIZE, flush_period_s: float = FLUSH_PERIOD_S) -> None:
        if max_bytes < 0:
            raise RecordingError(f'max_bytes must be >= 0 (0 = no limit), got {max_bytes!r}.')
        if not max_duration_s >= 0:
            raise RecordingError(f'max_duration_s must be >= 0 (0 = no limit), got '
                                 f'{max_duration_s!r}.')
        self.directory = Path(directory)
        self.max_bytes = int(max_bytes)
        self.max_duration_ns = round(max_duration_s * 1e9)
        self._chunk_size = chunk_size
        self._flush_period_s = flush_period_s
        self._lock = threading.RLock()
        self._channels: list[tuple[str, str, ros_qos.QosProfile]] = []
        self._channel_ids: dict[tuple[str, str, str], int] = {}
        self._metadata: dict[str, dict[str, str]] = {}  # repeated at the start of each file
        self._file_ids: dict[int, int] = {}  # our channel id -> the open file's
        self._bytes = 0  # message bytes in the open file
        self._first_ns: int | None = None  # log time of the open file's first message
        self._last_ns = 0
        self._count = 0  # messages in the open file
        self._previous_messages = 0  # in the files this recorder finished
        self._closed = False
        if self.directory.exists() and not self.directory.is_dir():
            raise RecordingError(f'{self.directory} is a file; a split recording is a '
                                 f'directory.')
        if append and self.directory.is_dir():
            self._lock_fd = _lock(self.directory)
            _repair(self.directory)
            existing = split_files(self.directory)
            self._index = _index_of(existing[-1]) + 1 if existing else 0
        else:
            try:
                self.directory.mkdir()  # atomic: refuses an existing directory
            except FileExistsError as e:
                raise RecordingError(f'{self.directory} exists already, not overwriting.') \
                    from e
            except OSError as e:
                raise RecordingError(f'Cannot create recording directory {self.directory}: '
                                     f'{e.strerror or e}') from e
            self._lock_fd = _lock(self.directory)
            self._index = 0
        try:
            self._recorder = self._open(self._index)
        except RecordingError:
            os.close(self._lock_fd)
            raise

    # ------------------------------------------------------------------ Recorder protocol
    @property
    def error(self) -> str | None:
        """Why recording stopped, or None while it works."""
        return self._recorder.error

    @property
    def path(self) -> Path:
        """The file being written."""
        return self._recorder.path

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def message_count(self) -> int:
        """Messages this recorder wrote, over all its files."""
        return self._previous_messages + self._count

    def add_channel(self, topic: str, typename: str, qos: ros_qos.QosProfile) -> int:
        """As ``McapRecorder.add_channel``; the id stays valid in every later file."""
        key = (topic, typename, ros_qos.offered_qos_yaml(qos))
        with self._lock:
            if key in self._channel_ids:
                return self._channel_ids[key]
            channel = len(self._channels) + 1
            self._file_ids[channel] = self._recorder.add_channel(topic, typename, qos)
            self._channels.append((topic, typename, qos))
            self._channel_ids[key] = channel
            return channel

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """As ``McapRecorder.add_metadata``; the record is repeated in every later file."""
        with self._lock:
            self._recorder.add_metadata(name, data)
            self._metadata[name] = dict(data)

    def write(self, channel: int, cdr: bytes, log_time_ns: int, publish_time_ns: int) -> None:
        """As ``McapRecorder.write``."""
        self.write_many(((channel, cdr, log_time_ns, publish_time_ns),))

    def write_many(self, messages: Iterable[tuple[int, bytes, int, int]]) -> None:
        """As ``McapRecorder.write_many``; opens the next file first if the open one is full.

        The batch goes into one file whole, so a step handed over in one call is never split.
        """
        batch = list(messages)
        if not batch:
            return
        with self._lock:
            if self._count and self._full(batch[0][2]):
                self._rotate()
            ids = self._file_ids
            try:
                mapped = [(ids[channel], data, log, pub) for channel, data, log, pub in batch]
            except KeyError as e:
                raise ValueError(f'Unknown channel id {e}; call add_channel first.') from None
            self._recorder.write_many(mapped)
            self._count += len(mapped)
            self._bytes += sum(len(m[1]) for m in mapped)
            if self._first_ns is None:
                self._first_ns = min(m[2] for m in mapped)
            self._last_ns = max(self._last_ns, max(m[2] for m in mapped))

    def flush(self, sync: bool = False) -> None:
        """As ``McapRecorder.flush``."""
        with self._lock:
            self._recorder.flush(sync)

    def close(self) -> None:
        """Finish the open file and write ``metadata.yaml``; safe to call again."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._finish_file()
            finally:
                os.close(self._lock_fd)

    def __enter__(self) -> SplitRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ internals
    def _full(self, next_log_ns: int) -> bool:
        if self.max_bytes and self._bytes >= self.max_bytes:
            return True
        return bool(self.max_duration_ns and self._first_ns is not None
                    and next_log_ns - self._first_ns >= self.max_duration_ns)

    def _open(self, index: int) -> McapRecorder:
        recorder = McapRecorder(split_path(self.directory, index), chunk_size=self._chunk_size,
                                flush_period_s=self._flush_period_s)
        try:
            self._file_ids = {channel: recorder.add_channel(*spec)
                              for channel, spec in enumerate(self._channels, 1)}
            for name, data in self._metadata.items():
                recorder.add_metadata(name, data)
        except RecordingError:
            recorder.close()
            raise
        return recorder

    def _rotate(self) -> None:
        self._finish_file()
        self._index += 1
        self._recorder = self._open(self._index)

    def _finish_file(self) -> None:
        recorder = self._recorder
        recorder.close()  # fsyncs the file; raises (RecordingError) if it cannot finish it
        self._previous_messages += self._count
        self._count, self._bytes, self._first_ns, self._last_ns = 0, 0, None, 0
        self._write_metadata_yaml()

    def _write_metadata_yaml(self) -> None:
        """Write ``metadata.yaml`` for the finished files (fsynced, renamed over the old one)."""
        target = self.directory / METADATA_FILE
        temporary = target.with_name(target.name + '.tmp')
        info = bag_metadata(split_files(self.directory))  # all finished: called between files
        info['rosbag2_bagfile_information']['custom_data'] = {
            'growspace_split_max_bytes': str(self.max_bytes),
            'growspace_split_max_duration_ns': str(self.max_duration_ns)}
        with contextlib.suppress(OSError):  # a full disk must not lose the finished file
            with open(temporary, 'w') as stream:
                yaml.safe_dump(info, stream, sort_keys=False)
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(temporary, target)
            _fsync_directory(self.directory)


def bag_metadata(files: list[Path]) -> dict:
    """rosbag2's ``metadata.yaml`` content (version 9) for finished MCAP files of one directory,
    from their summaries (a file without a readable summary is listed without statistics)."""
    from mcap.reader import SeekingReader

    topics: dict[tuple[str, str], dict] = {}
    entries = []
    start = end = None
    total = 0
    for path in files:
        entry: dict = {'path': path.name}
        try:
            with open(path, 'rb') as stream:
                summary = SeekingReader(stream).get_summary()
        except Exception:  # noqa: BLE001 - damaged: listed, not counted
            summary = None
        if summary is not None and summary.statistics is not None:
            stats = summary.statistics
            count = stats.message_count
            entry.update({'starting_time': {'nanoseconds_since_epoch': stats.message_start_time},
                          'duration': {'nanoseconds': stats.message_end_time
                                       - stats.message_start_time},
                          'message_count': count})
            if count:
                start = stats.message_start_time if start is None else \
                    min(start, stats.message_start_time)
                end = stats.message_end_time if end is None else max(end, stats.message_end_time)
            total += count
            for cid, channel in summary.channels.items():
                schema = summary.schemas.get(channel.schema_id)
                key = (channel.topic, schema.name if schema else '')
                topic = topics.setdefault(key, {'topic_metadata': {
                    'name': channel.topic, 'type': key[1], 'serialization_format': 'cdr',
                    'offered_qos_profiles': yaml.safe_load(
                        channel.metadata.get('offered_qos_profiles', '') or '[]') or [],
                    'type_description_hash': channel.metadata.get('topic_type_hash', '')},
                    'message_count': 0})
                topic['message_count'] += stats.channel_message_counts.get(cid, 0)
        entries.append(entry)
    return {'rosbag2_bagfile_information': {
        'version': 9, 'storage_identifier': 'mcap',
        'duration': {'nanoseconds': 0 if start is None else end - start},
        'starting_time': {'nanoseconds_since_epoch': start or 0},
        'message_count': total, 'topics_with_message_count': list(topics.values()),
        'compression_format': '', 'compression_mode': '',
        'relative_file_paths': [p.name for p in files], 'files': entries,
        'custom_data': {}, 'ros_distro': 'jazzy'}}


def _index_of(path: Path) -> int:
    return int(path.stem.rsplit('_', 1)[1])


def _fsync_directory(directory: Path) -> None:
    """Make a rename in ``directory`` durable (POSIX: the directory entry is data too)."""
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
