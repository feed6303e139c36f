"""``McapRecorder``: one recording file, never overwritten, finished on exit and on signals."""

from __future__ import annotations

import atexit
from collections.abc import Iterable, Iterator
import contextlib
import os
from pathlib import Path
import signal
import threading
import time
from typing import Any, BinaryIO
import weakref

import mcap

from growspace_sim import __version__
from growspace_sim.recording.chunk_writer import ChunkedWriter
from growspace_sim.ros import qos as ros_qos, types

PROFILE = 'ros2'
CHUNK_SIZE = 1024 * 1024  # B of uncompressed messages per chunk; what a hard kill can lose
FLUSH_PERIOD_S = 1.0  # close the open chunk at least this often, so slow runs lose little too
LIBRARY = f'growspace_sim {__version__}; mcap {mcap.__version__}'

_open_recorders: weakref.WeakSet[McapRecorder] = weakref.WeakSet()


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
            raise RecordingError(io_error_text(f'Cannot create recording {self.path}', e,
                                               self.path)) from e
        stat = os.fstat(self._stream.fileno())
        # The file this recorder created (None: it replaced one it was asked to overwrite).
        self._created = None if overwrite else (stat.st_dev, stat.st_ino)
        self._writer = ChunkedWriter(self._stream, chunk_size)
        try:
            self._writer.start(profile=PROFILE, library=LIBRARY)
        except OSError as e:
            self._abandon()
            raise RecordingError(io_error_text(f'Cannot write recording {self.path}', e,
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

    def flush(self, sync: bool = False) -> None:
        """Close the open chunk and push everything to the OS (a hard kill then loses nothing).

        Args:
            sync: Also have the OS put it on the disk (``fsync``), so that a power cut loses
                nothing either (costs a disk write: for steps that last minutes or more).

        Raises:
            RecordingError: The recorder is closed or failed, or writing failed now.
        """
        with self._lock:
            self._check_usable()
            with self._io_errors():
                self._writer.flush()
                if sync:
                    self._stream.flush()
                    os.fsync(self._stream.fileno())
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
                self._error = io_error_text(f'Cannot finish recording {self.path}', e, self.path)
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
        self._error = io_error_text(f'Cannot write recording {self.path}', error, self.path)
        self._abandon()
        raise RecordingError(self._error + _RECOVER_HINT.format(path=self.path)) from error

    def _abandon(self) -> None:
        # The buffered tail cannot be written either; close without raising again.
        writer = getattr(self, '_writer', None)
        if writer is not None:
            writer.abandon()
        with contextlib.suppress(OSError, ValueError):
            self._stream.close()
        self._remove_if_nothing_written()

    def _remove_if_nothing_written(self) -> None:
        """Remove the file if this recorder created it and not one byte of it reached the disk
        (full at start-up): an empty file is no recording, and left behind it would make the
        next start refuse the path as existing. Any other file is kept, whatever its size."""
        created = getattr(self, '_created', None)
        if created is None:
            return
        with contextlib.suppress(OSError):
            stat = os.stat(self.path)
            if (stat.st_dev, stat.st_ino) == created and stat.st_size == 0:
                os.unlink(self.path)


_RECOVER_HINT = ('. Messages in complete chunks are kept: '
                 '`growspace-replay recover {path} FIXED.mcap` copies them into a new file.')


def io_error_text(what: str, error: OSError, path: Path) -> str:
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
