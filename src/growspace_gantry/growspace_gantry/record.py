"""The gantry node's own recording, in the simulator's format (``docs/recording.md``).

Every message in and out is recorded with the wall time it was handled at. A step's answer
(``step_result``) is written, and the open chunk put on the disk (fsync), BEFORE it is
published: a step the runner saw answered is in the recording even if the node is killed or
the power cut the next instant, which is what lets a restarted node continue the episode
(``resume.py``) with nothing lost and nothing done twice. A step lasts a growth period on the
rig, so a chunk and a disk write per step cost nothing.

A failing recorder (disk full, file system gone) never stops the machine's safety: the node
reports it once, records no more, and refuses every later command and reset (``stopped``), so
nothing moves or grows that the recording would not hold. A person frees the disk and restarts
gantry_node with ``resume_path``, which goes on from the last recorded step.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from growspace_sim.ros.interface import Topic


class NodeRecording:
    """Channels, metadata and writes of one node's recorder (None: nothing recorded).

    Args:
        recorder: a ``McapRecorder`` or ``SplitRecorder``, or None.
        transport: the node's transport (topic names, the clock).
        warn: the node's throttled warning log, (key, text).
    """

    def __init__(self, recorder: Any, transport: Any,
                 warn: Callable[[str, str], object]) -> None:
        self.recorder = recorder
        self.transport = transport
        self.warn = warn
        self._channels: dict[str, int] = {}
        self.stopped = ''  # why the recording stopped for good ('' while it records)

    def start(self, topics: Iterable[Topic], metadata: dict[str, dict[str, str]]) -> None:
        """Register each topic as a channel and write the metadata records."""
        if self.recorder is None:
            return
        try:
            for t in topics:
                self._channels[t.key] = self.recorder.add_channel(
                    self.transport.resolve(t.name), t.typename, t.qos)
            for name, data in metadata.items():
                self.recorder.add_metadata(name, data)
        except Exception as e:  # noqa: BLE001 - recording never stops the machine's safety
            self._failed(e)

    def received(self, key: str, handler: Callable[[Any, bytes], None]) -> Callable:
        """``handler`` for an input, recording each message before it is handled."""
        def receive(msg: Any, cdr: bytes) -> None:
            self.write(key, cdr)
            handler(msg, cdr)
        return receive

    def write(self, key: str, cdr: bytes, flush: bool = False) -> None:
        """Record one message; ``flush``: put it (and all before it) on the disk now."""
        channel = self._channels.get(key)
        if channel is None:
            return
        now = self.transport.now_ns()
        try:
            self.recorder.write_many([(channel, cdr, now, now)])
            if flush:
                self.recorder.flush(sync=True)
        except Exception as e:  # noqa: BLE001 - same
            self._failed(e)

    def wants(self, key: str) -> bool:
        """Whether messages of ``key`` are recorded."""
        return key in self._channels

    def _failed(self, error: Exception) -> None:
        if getattr(self.recorder, 'error', None) is None:
            self.warn('recorder', f'recorder: a message was not recorded: {error}')
            return
        self._channels.clear()
        self.stopped = (f'recording stopped ({error}): free the disk, then restart gantry_node '
                        'with resume_path')
        self.warn('recorder:stopped', f'{self.stopped}; until then every command is refused')

    def close(self) -> None:
        """Finish the recording (idempotent)."""
        recorder, self.recorder = self.recorder, None
        self._channels.clear()
        if recorder is not None:
            try:
                recorder.close()
            except Exception as e:  # noqa: BLE001 - shutting down goes on
                self.warn('recorder', f'recorder close failed: {e}')
