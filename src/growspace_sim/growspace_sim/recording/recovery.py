"""Recover a damaged recording: copy every readable record into a new, finished file."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, BinaryIO

from mcap.records import Channel, Message, Metadata, Schema
from mcap.summary import Summary

from growspace_sim.recording.recorder import io_error_text, McapRecorder, RecordingError
from growspace_sim.recording.scan import (
    Damage, damage_metadata, McapScan, RECOVERY_METADATA)


@dataclasses.dataclass
class RecoveryReport:
    """What ``recover`` found in a damaged file."""

    messages: int  # messages copied
    chunks: int  # chunks read whole
    metadata: int  # metadata records copied
    complete: bool  # the source had its data-end record (it was not truncated)
    stopped_at: int  # byte offset where reading stopped
    reason: str  # why reading stopped short of the data end ('' if it did not)
    skipped: list[Damage] = dataclasses.field(default_factory=list)  # unreadable parts


def readable_summary(stream: BinaryIO) -> Summary | None:
    """A file's summary section, or None if it has none or it is damaged (CRC checked)."""
    from mcap.reader import SeekingReader

    try:
        return SeekingReader(stream, validate_crcs=True).get_summary()
    except Exception:  # noqa: BLE001 - truncated, corrupt or absent: read without it
        return None


def recover(src: str | os.PathLike, dst: str | os.PathLike, *,
            overwrite: bool = False) -> RecoveryReport:
    """Copy every readable record of a damaged MCAP file into a new, finished file.

    Reads the file front to back: schemas, channels, metadata and each chunk whose bytes are
    complete, decompress and match their CRC. A chunk that fails is skipped and listed in the
    report, and reading goes on with the next record; where the record framing itself is
    broken, it resumes at the next chunk the summary names (if the summary is readable), else
    it stops there. A hard kill loses only the chunk that was open; a flipped byte only its
    chunk. Sequence numbers are renumbered from 1 per channel, which keeps those of a file this
    recorder wrote. What was skipped is written into the new file as the metadata record
    ``growspace_recovery``, which ``replay.Bag`` reads as the file's damage.

    Args:
        src: The damaged recording.
        dst: The new recording (same schemas, channels, metadata and message bytes).
        overwrite: Replace ``dst`` if it exists.

    Returns:
        A report of what was copied and what was skipped.

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
    messages = metadata_count = 0
    if Path(dst).exists() and Path(dst).resolve() == src.resolve():
        stream.close()
        raise RecordingError(f'recover needs a new output file, not {src} itself.')
    with stream:
        summary = readable_summary(stream)
        if summary is not None:  # a chunk holding a file's schemas may be the lost one
            schemas.update(summary.schemas)
            channels.update(summary.channels)
        scan = McapScan(stream, summary.chunk_indexes if summary is not None else ())
        records = scan.records()
        try:
            first = next(records, None)
        except ValueError as e:
            raise RecordingError(f'{src} is not an MCAP file ({e}).') from e
        with McapRecorder(dst, overwrite=overwrite, flush_period_s=0) as out:
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

            if first is not None:
                absorb(first)
            for record in records:
                absorb(record)
            if scan.damage:  # so readers of the new file still know where its holes are
                writer.add_metadata(RECOVERY_METADATA, damage_metadata(src.name, scan.damage))
    return RecoveryReport(messages, scan.chunks_read, metadata_count, scan.complete,
                          scan.stopped_at, scan.reason, scan.damage)
