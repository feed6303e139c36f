"""Recover a recording cut short by a crash: copy its complete chunks into a new file."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk, StreamReader

from growspace_sim.recording.recorder import io_error_text, McapRecorder, RecordingError


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
        raise RecordingError(io_error_text(f'Cannot open {src}', e, src)) from e
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
