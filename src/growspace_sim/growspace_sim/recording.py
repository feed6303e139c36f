"""Record chamber topics to MCAP the way rosbag2 does (profile ``ros2``), and recover broken files.

A recording is one bare ``.mcap`` file that Jazzy ``ros2 bag info/play``, Foxglove, ``rosbags``
and ``mcap_ros2`` read (the rosbag2 MCAP storage conventions, docs/recording.md):

- header profile ``ros2``; one ``ros2msg`` schema per type (the concatenated definition from
  ``ros.types.msgdef``); channels with ``message_encoding='cdr'`` and the metadata
  ``offered_qos_profiles`` (rosbag2 v9 YAML) and ``topic_type_hash`` (RIHS01);
- messages are the exact CDR bytes put on the wire, encapsulation header included;
- zstd chunks of at most ``chunk_size`` bytes, also closed every ``flush_period_s`` seconds, so a
  hard kill loses at most the open chunk: ``recover()`` copies every complete chunk of a file
  that has no summary into a fresh file;
- a metadata record ``growspace`` with the effective config, seed, software version and the
  chamber geometry (``growspace_metadata``).

The chamber's side of the contract (topics, ``chamber/config`` payload, the ``growspace``
metadata) lives in ``growspace_sim.node.interface``; the names below re-export it because they
are part of the file format.

Example:
    with McapRecorder('run.mcap') as rec:
        ch = rec.add_channel('/growspace/step_result', types.STEP_RESULT, qos.DEFAULT)
        rec.write(ch, types.serialize(msg, types.STEP_RESULT), t_ns, t_ns)
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import os
from pathlib import Path
import queue
import signal
import struct
import threading
import time
from typing import Any, BinaryIO, Callable, Iterable, Iterator
import weakref
import zlib

import mcap
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Message,
                          Metadata, MetadataIndex, Schema, Statistics, SummaryOffset)
from mcap.stream_reader import breakup_chunk, StreamReader
import zstandard

from growspace_sim import __version__
from growspace_sim.node.interface import (  # noqa: F401 - re-exported: part of the file format
    FORMAT, METADATA_NAME, config_dict, config_json, digit_fingerprint, growspace_metadata)
from growspace_sim.ros import qos as ros_qos, types

PROFILE = 'ros2'
CHUNK_SIZE = 1024 * 1024  # B of uncompressed messages per chunk; what a hard kill can lose
FLUSH_PERIOD_S = 1.0  # close the open chunk at least this often, so slow runs lose little too
LIBRARY = f'growspace_sim {__version__}; mcap {mcap.__version__}'

_open_recorders: weakref.WeakSet[McapRecorder] = weakref.WeakSet()


MAGIC = b'\x89MCAP0\r\n'
# Record layouts of the MCAP spec, packed by hand on the hot path (mcap's RecordBuilder is a
# Python call per field); test_recording checks the bytes against mcap's own writer.
_MESSAGE_HEADER = struct.Struct('<BQHIQQ')  # opcode, record length, channel, sequence, times
_MESSAGE_FIXED = 2 + 4 + 8 + 8  # bytes of a Message record before its data
_MESSAGE_OP = int(Opcode.MESSAGE)  # an int: packing the IntEnum costs a conversion per message
_CHUNK_HEADER = struct.Struct('<BQQQQII4sQ')  # ... crc, len('zstd'), 'zstd', compressed size
_RECORD_HEADER = struct.Struct('<BQ')  # opcode, record length
_INDEX_HEADER = struct.Struct('<HI')  # MessageIndex: channel, bytes of (time, offset) pairs
_QUEUED_CHUNKS = 8  # chunks waiting for the disk at most; then write() waits (never drops)
ZSTD_LEVEL = 1  # on chamber data as small as level 3 (within 1 %) and a third faster


def _record_bytes(*records: Any) -> bytes:
    builder = RecordBuilder()
    for record in records:
        record.write(builder)
    return builder.end()


class _ChunkedWriter:
    """An MCAP writer with a fast message path; compression and disk I/O on a worker thread.

    ``mcap.writer.Writer`` builds each message record from Python objects (about 35 us per
    message), which alone made recording 60 % slower than the chamber itself. Here a batch of
    messages (one per chamber tick) costs one call, and a message one ``struct.pack_into`` and
    one copy into the open chunk's buffer. Buffers are reused: a fresh megabyte per chunk cost
    more in page faults than compressing it. Full chunks go to a worker thread that compresses
    them (zstd releases the GIL) and writes each with its message indexes in one write.
    Schemas, channels and metadata are written outside chunks as they come, so a truncated file
    still has them. The file is laid out as ``mcap.writer.Writer`` lays it out. The methods
    mirror ``mcap.writer.Writer`` and are called under the recorder's lock.
    """

    def __init__(self, stream: BinaryIO, chunk_size: int, level: int = ZSTD_LEVEL) -> None:
        self._stream = stream
        self._chunk_size = chunk_size
        self._compressor = zstandard.ZstdCompressor(level=level)
        self._pos = 0
        # A message that starts below chunk_size fits, so small ones never grow a buffer.
        self._buffer_size = chunk_size + 64 * 1024
        self._free: list[bytearray] = []  # buffers the worker is done with
        self._buffer = bytearray(self._buffer_size)  # the open chunk's records
        self._chunk_len = 0  # bytes used in _buffer
        self._index: dict[int, list[int]] = {}  # channel -> [log_time, offset, log_time, ...]
        self._chunk_start = self._chunk_end = 0
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._counts: dict[int, int] = {}  # messages per channel (= the last sequence number)
        self._metadata_count = 0
        self._start_time = self._end_time = -1  # over the chunks handed to the worker [ns]
        self.error: BaseException | None = None  # set by the worker; raised to the caller
        self._jobs: queue.Queue[Callable[[], None] | None] = queue.Queue(_QUEUED_CHUNKS)
        self._worker: threading.Thread | None = None

    def start(self, profile: str, library: str) -> None:
        # Synchronous, so an unwritable target fails in the recorder's constructor.
        self._write(MAGIC + _record_bytes(Header(profile=profile, library=library)))
        self._stream.flush()
        self._worker = threading.Thread(target=self._work, name='mcap-recorder', daemon=True)
        self._worker.start()

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas[schema.id] = schema
        self._submit(lambda: self._write(_record_bytes(schema)))
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str]) -> int:
        channel = Channel(id=len(self._channels) + 1, topic=topic,
                          message_encoding=message_encoding, schema_id=schema_id,
                          metadata=dict(metadata))
        self._channels[channel.id] = channel
        self._counts[channel.id] = 0
        self._submit(lambda: self._write(_record_bytes(channel)))
        return channel.id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        record = _record_bytes(Metadata(name=name, metadata=dict(data)))
        self._metadata_count += 1

        def job() -> None:
            self._metadata_indexes.append(MetadataIndex(offset=self._pos, length=len(record),
                                                        name=name))
            self._write(record)
            self._stream.flush()
        self._submit(job)

    def add_messages(self, messages: Iterable[tuple[int, bytes, int, int]]) -> None:
        """Append ``(channel, data, log_time, publish_time)`` messages to the open chunk.

        Each channel's messages get sequence numbers 1, 2, ...

        Raises:
            ValueError: A channel id is unknown or a time is outside [0, 2**64) ns; the
                messages before it are kept.
        """
        counts, index, buffer = self._counts, self._index, self._buffer
        pack_into = _MESSAGE_HEADER.pack_into
        offset, start, end = self._chunk_len, self._chunk_start, self._chunk_end
        try:
            for channel, data, log_time, publish_time in messages:
                sequence = counts[channel] + 1
                size = len(data)
                stop = offset + 9 + _MESSAGE_FIXED + size
                if stop > len(buffer):
                    buffer.extend(bytes(stop - len(buffer)))
                pack_into(buffer, offset, _MESSAGE_OP, _MESSAGE_FIXED + size, channel,
                          sequence, log_time, publish_time)
                buffer[stop - size:stop] = data
                # Only now is the record counted: an exception (or a signal) above leaves no
                # half record in the chunk.
                counts[channel] = sequence
                if not offset:
                    start = end = log_time
                elif log_time < start:
                    start = log_time
                elif log_time > end:
                    end = log_time
                channel_index = index.get(channel)
                if channel_index is None:
                    channel_index = index[channel] = []
                channel_index += (log_time, offset)
                offset = stop
                if offset >= self._chunk_size:
                    self._chunk_len, self._chunk_start, self._chunk_end = offset, start, end
                    self.flush(wait=False)
                    buffer, index, offset = self._buffer, self._index, 0
        except KeyError as e:
            raise ValueError(f'Unknown channel id {e}; call add_channel first.') from None
        except struct.error as e:
            raise ValueError(f'Times must be ints in [0, 2**64) ns: {e}.') from None
        finally:
            self._chunk_len, self._chunk_start, self._chunk_end = offset, start, end

    @property
    def message_count(self) -> int:
        return sum(self._counts.values())

    def flush(self, wait: bool = True) -> None:
        """Hand the open chunk to the worker; with ``wait``, until the OS has it."""
        if self._chunk_len:
            buffer, size, index = self._buffer, self._chunk_len, self._index
            start, end = self._chunk_start, self._chunk_end
            # list.pop is atomic: the worker appends buffers it is done with concurrently.
            self._buffer = self._free.pop() if self._free else bytearray(self._buffer_size)
            self._index, self._chunk_len = {}, 0
            if self._start_time < 0:
                self._start_time, self._end_time = start, end
            else:
                self._start_time = min(self._start_time, start)
                self._end_time = max(self._end_time, end)
            self._submit(lambda: self._write_chunk(buffer, size, index, start, end))
        if wait:
            self._jobs.join()
            self._raise_worker_error()

    def finish(self) -> None:
        """Write the last chunk, the summary and the footer; stop the worker."""
        self.flush(wait=False)
        self._submit(self._write_summary)
        self._stop()
        self._raise_worker_error()

    def abandon(self) -> None:
        """Stop the worker; queued data is dropped (the file is already failing)."""
        if self.error is None:
            self.error = OSError('recording abandoned')
        self._stop()

    # ------------------------------------------------------------------ worker side
    def _submit(self, job: Callable[[], None]) -> None:
        self._raise_worker_error()
        self._jobs.put(job)  # blocks while _QUEUED_CHUNKS wait: back-pressure, no loss

    def _raise_worker_error(self) -> None:
        if self.error is not None:
            raise self.error

    def _stop(self) -> None:
        if self._worker is not None and self._worker.is_alive():
            self._jobs.put(None)
            self._worker.join()

    def _work(self) -> None:
        while True:
            job = self._jobs.get()
            try:
                if job is None:
                    return
                if self.error is None:
                    job()
            except BaseException as e:  # noqa: BLE001 - handed over to the writing thread
                self.error = e
            finally:
                self._jobs.task_done()

    def _write(self, data: bytes) -> None:
        self._stream.write(data)
        self._pos += len(data)

    def _write_chunk(self, buffer: bytearray, size: int, index: dict[int, list[int]],
                     start: int, end: int) -> None:
        with memoryview(buffer) as view:
            chunk = view[:size]
            compressed = self._compressor.compress(chunk)
            crc = zlib.crc32(chunk)
            chunk.release()
        self._free.append(buffer)
        record_length = _CHUNK_HEADER.size - 9 + len(compressed)
        parts = [_CHUNK_HEADER.pack(Opcode.CHUNK, record_length, start, end, size, crc, 4,
                                    b'zstd', len(compressed)), compressed]
        chunk_start = self._pos
        offsets = {}
        index_start = position = chunk_start + 9 + record_length
        for channel_id, pairs in index.items():
            offsets[channel_id] = position
            length = _INDEX_HEADER.size + 8 * len(pairs)
            parts += (_RECORD_HEADER.pack(Opcode.MESSAGE_INDEX, length),
                      _INDEX_HEADER.pack(channel_id, 8 * len(pairs)),
                      struct.pack(f'<{len(pairs)}Q', *pairs))
            position += _RECORD_HEADER.size + length
        # One write (one GIL release) for the chunk and its indexes.
        self._write(b''.join(parts))
        self._stream.flush()
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start, message_end_time=end, chunk_start_offset=chunk_start,
            chunk_length=9 + record_length, message_index_offsets=offsets,
            message_index_length=position - index_start, compression='zstd',
            compressed_size=len(compressed), uncompressed_size=size))

    def _write_summary(self) -> None:
        self._write(_record_bytes(DataEnd(data_section_crc=0)))
        summary_start = self._pos
        builder = RecordBuilder()
        offsets = []
        groups = (
            (Opcode.SCHEMA, list(self._schemas.values())),
            (Opcode.CHANNEL, list(self._channels.values())),
            (Opcode.STATISTICS, [Statistics(
                attachment_count=0, channel_count=len(self._channels),
                channel_message_counts=dict(self._counts),
                chunk_count=len(self._chunk_indexes), message_count=self.message_count,
                message_end_time=max(self._end_time, 0),
                message_start_time=max(self._start_time, 0),
                metadata_count=self._metadata_count, schema_count=len(self._schemas))]),
            (Opcode.CHUNK_INDEX, self._chunk_indexes),
            (Opcode.METADATA_INDEX, self._metadata_indexes),
        )
        for opcode, records in groups:
            group_start = builder.count
            for record in records:
                record.write(builder)
            if builder.count > group_start:
                offsets.append(SummaryOffset(group_opcode=opcode,
                                             group_start=summary_start + group_start,
                                             group_length=builder.count - group_start))
        summary_offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack('<BQQQ', Opcode.FOOTER, 8 + 8 + 4, summary_start,
                                     summary_offset_start), crc)
        self._write(summary)
        self._write(_record_bytes(Footer(summary_start=summary_start,
                                         summary_offset_start=summary_offset_start,
                                         summary_crc=crc)) + MAGIC)
        self._stream.flush()


class RecordingError(Exception):
    """Raised when a recording cannot be created, written or read; the message names the file."""


class McapRecorder:
    """Write pre-serialised ROS 2 messages into a new MCAP file (profile ``ros2``, zstd chunks).

    Thread-safe: channels may be added and messages written from several callbacks. After an
    I/O error (disk full, file system gone) the recorder stops: that call and every later
    ``write`` raise ``RecordingError``, and what was written until the last complete chunk stays
    recoverable with ``recover()``. The process is not affected otherwise.

    Args:
        path: The ``.mcap`` file to create.
        overwrite: Replace an existing file instead of refusing to.
        chunk_size: Uncompressed bytes per chunk; smaller loses less on a hard kill.
        flush_period_s: Close the open chunk when it is older than this [s]; 0 = only by size.

    Raises:
        RecordingError: The file exists (and ``overwrite`` is false), is a directory, its
            directory does not exist, or it cannot be written.
    """

    def __init__(self, path: str | os.PathLike, *, overwrite: bool = False,
                 chunk_size: int = CHUNK_SIZE, flush_period_s: float = FLUSH_PERIOD_S) -> None:
        self.path = Path(path)
        self.flush_period_s = flush_period_s
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str, str], int] = {}
        self._error: str | None = None
        self._closed = False
        if self.path.is_dir():
            raise RecordingError(f'{self.path} is a directory; give the path of a .mcap file.')
        try:
            # 'x' makes the no-overwrite check and the creation one atomic step.
            self._stream: BinaryIO = open(self.path, 'wb' if overwrite else 'xb')
        except FileExistsError as e:
            raise RecordingError(f'{self.path} exists already, not overwriting.') from e
        except OSError as e:
            raise RecordingError(_io_message(f'Cannot create recording {self.path}', e,
                                             self.path)) from e
        self._writer = _ChunkedWriter(self._stream, chunk_size)
        try:
            self._writer.start(profile=PROFILE, library=LIBRARY)
        except OSError as e:
            self._abandon()
            raise RecordingError(_io_message(f'Cannot write recording {self.path}', e,
                                             self.path)) from e
        self._last_flush = time.monotonic()
        _open_recorders.add(self)

    # ------------------------------------------------------------------ writing
    def add_channel(self, topic: str, typename: str, qos: ros_qos.QosProfile) -> int:
        """Register a topic (once per topic, type and QoS; repeated calls return the same id).

        Args:
            topic: The fully qualified ROS topic name, e.g. ``/growspace/step_result``.
            typename: The ROS type, e.g. ``growspace_msgs/msg/StepResult``.
            qos: The QoS the topic was published (or, for received topics, subscribed) with.

        Returns:
            The channel id to pass to ``write``.

        Raises:
            RecordingError: The recorder is closed or failed.
            KeyError: The type is unknown to ``ros.types``.
        """
        qos_yaml = ros_qos.offered_qos_yaml(qos)
        key = (topic, typename, qos_yaml)
        with self._lock:
            self._check_usable()
            if key in self._channels:
                return self._channels[key]
            with self._io_errors():
                schema_id = self._schemas.get(typename)
                if schema_id is None:
                    schema_id = self._writer.register_schema(
                        typename, 'ros2msg', types.msgdef(typename).encode())
                    self._schemas[typename] = schema_id
                channel = self._writer.register_channel(
                    topic, 'cdr', schema_id,
                    {'offered_qos_profiles': qos_yaml,
                     'topic_type_hash': types.type_hash(typename)})
            self._channels[key] = channel
            return channel

    def write(self, channel: int, cdr: bytes, log_time_ns: int, publish_time_ns: int) -> None:
        """Append one message.

        Args:
            channel: An id from ``add_channel``.
            cdr: The serialised message as on the wire (encapsulation header included).
            log_time_ns: When it was received/recorded [ns] (rosbag2's recv_timestamp).
            publish_time_ns: When it was published [ns] (rosbag2's send_timestamp).

        Raises:
            RecordingError: The recorder is closed or failed, or writing failed now.
            ValueError: The channel id is unknown or a time is out of range.
        """
        self.write_many(((channel, cdr, log_time_ns, publish_time_ns),))

    def write_many(self, messages: Iterable[tuple[int, bytes, int, int]]) -> None:
        """Append messages in order, e.g. everything a chamber tick published, in one call.

        Args:
            messages: ``(channel, cdr, log_time_ns, publish_time_ns)`` as for ``write``.

        Raises:
            RecordingError: The recorder is closed or failed, or writing failed now.
            ValueError: A channel id is unknown or a time is out of range (the messages
                before it are written).
        """
        with self._lock:
            self._check_usable()
            try:
                self._writer.add_messages(messages)
                if self.flush_period_s:
                    now = time.monotonic()
                    if now - self._last_flush >= self.flush_period_s:
                        self._writer.flush(wait=False)
                        self._last_flush = now
            except OSError as e:
                self._fail(e)

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return self._writer.message_count

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Write a metadata record now (it survives a later crash).

        Args:
            name: The record name, e.g. ``growspace``.
            data: String keys and values.

        Raises:
            RecordingError: The recorder is closed or failed, or writing failed now.
            TypeError: A key or value is not a string.
        """
        bad = [k for k, v in data.items() if not isinstance(k, str) or not isinstance(v, str)]
        if bad:
            raise TypeError(f'Metadata {name!r}: keys and values must be str; bad keys: {bad}')
        with self._lock:
            self._check_usable()
            with self._io_errors():
                self._writer.add_metadata(name, dict(data))

    def flush(self) -> None:
        """Close the open chunk and push everything to the OS (a hard kill then loses nothing).

        Raises:
            RecordingError: The recorder is closed or failed, or writing failed now.
        """
        with self._lock:
            self._check_usable()
            with self._io_errors():
                self._writer.flush()
                self._last_flush = time.monotonic()

    def close(self) -> None:
        """Finish the file (indexes, summary, footer) and close it; safe to call again.

        Raises:
            RecordingError: Finishing failed (the complete chunks remain recoverable).
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
            _open_recorders.discard(self)
            if self._error is not None:
                self._abandon()
                return
            try:
                self._writer.finish()
                os.fsync(self._stream.fileno())
                self._stream.close()
            except OSError as e:
                self._error = _io_message(f'Cannot finish recording {self.path}', e, self.path)
                self._abandon()
                raise RecordingError(self._error + _RECOVER_HINT.format(path=self.path)) from e

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def error(self) -> str | None:
        """Why recording stopped, or None while it works."""
        return self._error

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ internals
    def _check_usable(self) -> None:
        if self._error is not None:
            raise RecordingError(f'Recording to {self.path} stopped earlier: {self._error}')
        if self._closed:
            raise RecordingError(f'Recording to {self.path} is closed.')

    @contextlib.contextmanager
    def _io_errors(self) -> Iterator[None]:
        try:
            yield
        except OSError as e:
            self._fail(e)

    def _fail(self, error: OSError) -> None:
        self._error = _io_message(f'Cannot write recording {self.path}', error, self.path)
        self._abandon()
        raise RecordingError(self._error + _RECOVER_HINT.format(path=self.path)) from error

    def _abandon(self) -> None:
        # The buffered tail cannot be written either; close without raising again.
        writer = getattr(self, '_writer', None)
        if writer is not None:
            writer.abandon()
        with contextlib.suppress(OSError, ValueError):
            self._stream.close()


_RECOVER_HINT = ('. Messages in complete chunks are kept: '
                 '`growspace-replay recover {path} FIXED.mcap` copies them into a new file.')


def _io_message(what: str, error: OSError, path: Path) -> str:
    reason = error.strerror or str(error)
    if isinstance(error, FileNotFoundError) and not path.parent.exists():
        reason += f' (directory {path.parent} does not exist)'
    return f'{what}: {reason}'


@atexit.register
def _close_open_recorders() -> None:
    # Interpreter exit (also SystemExit, an uncaught exception) still finishes every file.
    for recorder in list(_open_recorders):
        with contextlib.suppress(Exception):
            recorder.close()


@contextlib.contextmanager
def stop_on_signals(signals: tuple[int, ...] = (signal.SIGTERM, signal.SIGINT)) -> Iterator[None]:
    """Turn SIGTERM (and SIGINT) into ``KeyboardInterrupt`` inside the block.

    Python's default SIGTERM action ends the process without running ``finally`` blocks, which
    would leave a recording without its summary. Inside this block the signal raises in the main
    thread instead, so ``with McapRecorder(...)`` finishes the file. rclpy installs an equivalent
    handler itself (``rclpy.init`` -> ExternalShutdownException); use this one without rclpy.
    Does nothing outside the main thread.

    Args:
        signals: The signals to convert.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt(f'signal {signal.Signals(signum).name}')

    previous = {s: signal.signal(s, handler) for s in signals}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


# ---------------------------------------------------------------------- recovery
@dataclasses.dataclass
class RecoveryReport:
    """What ``recover`` found in a damaged file."""

    messages: int  # messages copied
    chunks: int  # complete chunks read
    metadata: int  # metadata records copied
    complete: bool  # the source had its data-end record (it was not truncated)
    stopped_at: int  # byte offset where reading stopped
    reason: str  # why reading stopped ('' if the file ended normally)


def recover(src: str | os.PathLike, dst: str | os.PathLike, *,
            overwrite: bool = False) -> RecoveryReport:
    """Copy every readable record of a (truncated) MCAP file into a new, finished file.

    Reads the file front to back without its summary: schemas, channels, metadata and each chunk
    whose bytes are complete and whose CRC matches. Reading stops at the first truncated or
    corrupt record; a hard kill loses only the chunk that was open. Sequence numbers are
    renumbered from 1 per channel, which keeps those of a file this recorder wrote.

    Args:
        src: The damaged recording.
        dst: The new recording (same schemas, channels, metadata and message bytes).
        overwrite: Replace ``dst`` if it exists.

    Returns:
        A report of what was copied.

    Raises:
        RecordingError: ``src`` cannot be opened or is not MCAP, or ``dst`` cannot be written.
    """
    src = Path(src)
    try:
        stream = open(src, 'rb')
    except OSError as e:
        raise RecordingError(_io_message(f'Cannot open {src}', e, src)) from e
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages = chunks = metadata_count = 0
    complete, reason = False, ''
    if Path(dst).exists() and Path(dst).resolve() == src.resolve():
        raise RecordingError(f'recover needs a new output file, not {src} itself.')
    with stream, McapRecorder(dst, overwrite=overwrite, flush_period_s=0) as out:
        writer = out._writer  # noqa: SLF001 - raw records are copied, not re-serialised
        mapping: dict[int, int] = {}
        schema_map: dict[int, int] = {}

        def copy_message(msg: Message) -> None:
            nonlocal messages
            channel = channels.get(msg.channel_id)
            if channel is None:
                return
            if msg.channel_id not in mapping:
                schema = schemas.get(channel.schema_id)
                sid = 0
                if schema is not None:
                    if schema.id not in schema_map:
                        schema_map[schema.id] = writer.register_schema(
                            schema.name, schema.encoding, schema.data)
                    sid = schema_map[schema.id]
                mapping[msg.channel_id] = writer.register_channel(
                    channel.topic, channel.message_encoding, sid, dict(channel.metadata))
            writer.add_messages(((mapping[msg.channel_id], msg.data, msg.log_time,
                                  msg.publish_time),))
            messages += 1

        def absorb(record: Any) -> None:
            nonlocal metadata_count
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                copy_message(record)
            elif isinstance(record, Metadata):
                writer.add_metadata(record.name, dict(record.metadata))
                metadata_count += 1

        reader = StreamReader(stream, skip_magic=False, emit_chunks=True, validate_crcs=True)
        try:
            for record in reader.records:
                if isinstance(record, Chunk):
                    # Split before copying: a CRC error drops the whole chunk, not half of it.
                    inner = breakup_chunk(record, validate_crc=True)
                    chunks += 1
                    for item in inner:
                        absorb(item)
                elif isinstance(record, (DataEnd, Footer)):
                    complete = True
                    break
                else:
                    absorb(record)
        except Exception as e:  # noqa: BLE001 - any decoder failure means the rest is damaged
            reason = f'{type(e).__name__}: {e}'.rstrip(': ')
        stopped_at = stream.tell()
    return RecoveryReport(messages, chunks, metadata_count, complete, stopped_at, reason)
