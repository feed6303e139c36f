"""Reading an MCAP file record by record, skipping what cannot be read.

mcap's own readers raise at the first bad byte, so one flipped bit in a compressed chunk used to
end ``info``, ``check`` and ``recover`` there. Every MCAP record starts with its opcode and its
length (MCAP specification, "Records"), so a reader that frames records itself can drop one
that fails to parse, decompress or match its CRC, say where it was, and go on with the next.
Where even the framing is broken (a flipped length), reading resumes at the next chunk the
summary's chunk index names, if the file has a readable summary; otherwise it stops there.

``McapScan`` serves both the reader (``replay.Bag``) and ``recover``.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
import dataclasses
import io
import json
import os
import struct
from typing import BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, ChunkIndex, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from growspace_sim.recording.chunk_writer import MAGIC

Record = Schema | Channel | Message | Metadata
_PREFIX = struct.Struct('<BQ')  # every record: opcode, content length
_KNOWN = frozenset(int(op) for op in Opcode)
_PARSERS = {int(Opcode.SCHEMA): Schema, int(Opcode.CHANNEL): Channel,
            int(Opcode.METADATA): Metadata}


@dataclasses.dataclass(frozen=True)
class Damage:
    """A part of the file that could not be read and was skipped.

    Attributes:
        offset: Byte offset where the unreadable part starts (a record's first byte).
        end: Byte offset where reading went on, or the file size if it stopped there.
        what: 'chunk', or the kind of record, or 'records' where the framing was lost.
        reason: Why it could not be read (CRC mismatch, decompression error, ...).
        start_time: Earliest log time of the messages lost [ns], where the chunk index or the
            chunk's header says; None if unknown.
        end_time: Latest log time of the messages lost [ns], or None.
    """

    offset: int
    end: int
    what: str
    reason: str
    start_time: int | None = None
    end_time: int | None = None

    def __str__(self) -> str:
        times = '' if self.start_time is None else \
            f', log time {self.start_time / 1e9:.3f}-{self.end_time / 1e9:.3f} s'
        return f'{self.what} at byte {self.offset} ({self.end - self.offset} B{times}): ' \
               f'{self.reason}'


RECOVERY_METADATA = 'growspace_recovery'  # what ``recover`` skipped, kept in the new file


def damage_metadata(source: str, damage: Sequence[Damage]) -> dict[str, str]:
    """The metadata record ``recover`` writes: the source file and what it could not read."""
    return {'source': source,
            'skipped': json.dumps([dataclasses.asdict(part) for part in damage])}


def damage_from_metadata(metadata: dict[str, str]) -> list[Damage]:
    """The skipped parts a recovered file's metadata record lists (offsets in its source).

    Raises:
        ValueError: the record is not what ``damage_metadata`` writes.
    """
    try:
        source = metadata['source']
        return [Damage(**{**part, 'what': f'{part["what"]} of {source}'})
                for part in json.loads(metadata['skipped'])]
    except (KeyError, TypeError) as e:
        raise ValueError(f'bad {RECOVERY_METADATA!r} metadata record: {e!r}') from e


class McapScan:
    """Iterate the schemas, channels, messages and metadata of an MCAP file's data section.

    Args:
        stream: The file, opened for binary reading.
        chunk_indexes: The summary's chunk index records, if the file has a readable summary:
            they give a lost chunk's log-time range and where to resume after broken framing.

    After (or during) iteration: ``damage`` lists what was skipped, ``complete`` says whether the
    data section's end record was reached, ``stopped_at`` and ``reason`` say where and why
    reading stopped short of it.
    """

    def __init__(self, stream: BinaryIO, chunk_indexes: Sequence[ChunkIndex] = ()) -> None:
        self._stream = stream
        self._chunks = {c.chunk_start_offset: c for c in chunk_indexes}
        self._resume_points = sorted(self._chunks)
        self.damage: list[Damage] = []
        self.complete = False
        self.stopped_at = 0
        self.reason = ''
        self.chunks_read = 0

    def records(self) -> Iterator[Record]:
        """Yield the readable records in file order (those of a chunk as it holds them)."""
        stream = self._stream
        size = os.fstat(stream.fileno()).st_size
        stream.seek(0)
        if stream.read(len(MAGIC)) != MAGIC:
            raise ValueError('not an MCAP file (bad magic bytes)')
        pos = len(MAGIC)
        while True:
            prefix = stream.read(_PREFIX.size)
            if len(prefix) < _PREFIX.size:
                self._stop(pos, size, 'the file ends inside a record' if prefix
                           else "the file ends before the data section's end record")
                return
            opcode, length = _PREFIX.unpack(prefix)
            end = pos + _PREFIX.size + length
            if opcode not in _KNOWN or end > size:
                resume = next((p for p in self._resume_points if p > pos), None)
                if opcode in _KNOWN:
                    reason = (f'a {Opcode(opcode).name.lower()} record of {length} B would end '
                              f'{end - size} B past the end of the file (cut short, or its '
                              f'length field is damaged)')
                else:
                    reason = f'no record starts here (opcode 0x{opcode:02x}): broken framing'
                if resume is None:
                    self._stop(pos, size, reason)
                    return
                self._lose(pos, resume, 'records', reason)
                pos = resume
                stream.seek(pos)
                continue
            if opcode == Opcode.CHUNK:
                yield from self._chunk(pos, end, stream.read(length))
            elif opcode in _PARSERS:
                try:
                    record = _PARSERS[opcode].read(ReadDataStream(io.BytesIO(
                        stream.read(length))))
                except Exception as e:  # noqa: BLE001 - any parse failure: skip the record
                    self._lose(pos, end, _PARSERS[opcode].__name__.lower(), _text(e))
                else:
                    yield record
            elif opcode == Opcode.MESSAGE:  # a message outside chunks (unchunked files)
                try:
                    yield Message.read(ReadDataStream(io.BytesIO(stream.read(length))), length)
                except Exception as e:  # noqa: BLE001 - as above
                    self._lose(pos, end, 'message', _text(e))
            elif opcode in (Opcode.DATA_END, Opcode.FOOTER):
                self.complete = True
                self.stopped_at = pos
                return
            pos = end  # header, indexes, attachments: nothing a chamber reader needs
            stream.seek(pos)  # also where a consumer that used the stream between yields left it

    def _chunk(self, pos: int, end: int, content: bytes) -> Iterator[Record]:
        """The records of one chunk, or none and a ``Damage`` if any of it is unreadable."""
        index = self._chunks.get(pos)
        times = (index.message_start_time, index.message_end_time) if index else (None, None)
        try:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(content)))
            if index is None:
                times = (chunk.message_start_time, chunk.message_end_time)
            # Split before yielding: a chunk counts whole or not at all.
            inner = breakup_chunk(chunk, validate_crc=True)
        except Exception as e:  # noqa: BLE001 - CRC, zstd, lz4 or record errors alike
            self._lose(pos, end, 'chunk', _text(e), *times)
            return
        self.chunks_read += 1
        yield from inner

    def _lose(self, offset: int, end: int, what: str, reason: str,
              start_time: int | None = None, end_time: int | None = None) -> None:
        if start_time is None and what == 'records':  # the chunks the broken span covered
            covered = [self._chunks[p] for p in self._resume_points if offset <= p < end]
            if covered:
                start_time = min(c.message_start_time for c in covered)
                end_time = max(c.message_end_time for c in covered)
        self.damage.append(Damage(offset, end, what, reason, start_time, end_time))

    def _stop(self, pos: int, size: int, reason: str) -> None:
        self.stopped_at, self.reason = pos, reason
        if pos < size:
            self._lose(pos, size, 'records', reason)


def _text(error: Exception) -> str:
    return f'{type(error).__name__}: {error}'.rstrip(': ')
