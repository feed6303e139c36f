"""The MCAP chunk writer behind ``McapRecorder``: records packed by hand, chunks compressed and
written by a background thread, so a hard kill loses at most the open chunk.

Records follow the MCAP specification and are read back by mcap's own reader in the tests
(tests/recording/test_recording.py); ``scripts/bench_recording.py`` measures it against mcap's
writer.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
import queue
import struct
import threading
from typing import Any, BinaryIO
import zlib

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, ChunkIndex, DataEnd, Footer, Header, Metadata,
                          MetadataIndex, Schema, Statistics, SummaryOffset)
import zstandard


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


def record_bytes(*records: Any) -> bytes:
    builder = RecordBuilder()
    for record in records:
        record.write(builder)
    return builder.end()


class ChunkedWriter:
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
        self._write(MAGIC + record_bytes(Header(profile=profile, library=library)))
        self._stream.flush()
        self._worker = threading.Thread(target=self._work, name='mcap-recorder', daemon=True)
        self._worker.start()

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas[schema.id] = schema
        self._submit(lambda: self._write(record_bytes(schema)))
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str]) -> int:
        channel = Channel(id=len(self._channels) + 1, topic=topic,
                          message_encoding=message_encoding, schema_id=schema_id,
                          metadata=dict(metadata))
        self._channels[channel.id] = channel
        self._counts[channel.id] = 0
        self._submit(lambda: self._write(record_bytes(channel)))
        return channel.id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        record = record_bytes(Metadata(name=name, metadata=dict(data)))
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
        self._write(record_bytes(DataEnd(data_section_crc=0)))
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
        self._write(record_bytes(Footer(summary_start=summary_start,
                                        summary_offset_start=summary_offset_start,
                                        summary_crc=crc)) + MAGIC)
        self._stream.flush()
