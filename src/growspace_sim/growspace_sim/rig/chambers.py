"""The chambers ``growspace-rig`` drives, over the Gymnasium bridge's ``ChamberLink``.

- ``SimChamber``: the runner starts ``sim_node`` (lockstep) recording into the run directory,
  split by size and duration; on resume it starts it again with ``resume_path`` on that
  recording, so the simulator continues the same episode bit for bit;
- ``AttachedChamber``: a lockstep chamber someone started (``sim_node``, or ``gantry_node`` with
  ``camera_node``), attached by namespace.
"""

from __future__ import annotations

from collections.abc import Callable
import os
from pathlib import Path
import secrets
from typing import Any

import numpy as np

from growspace_sim.rig.rundir import RunDir, RunSettings
from growspace_sim.rig.runner import (
    Answer, recorded_episodes, RecordedStep, RigChamber, RunnerError)
from growspace_sim.ros import convert


class _LinkChamber:
    """The ``ChamberLink`` side shared by both chambers."""

    recording: Path | None = None
    simulated = False

    def __init__(self, settings: RunSettings, namespace: str) -> None:
        self.settings = settings
        self.namespace = namespace
        self.link: Any = None
        self._transport: Any = None

    def _connect(self, liveness: Any = None) -> None:
        from growspace_gym_bridge.link import ChamberLink
        from growspace_sim.node.rclpy_transport import RclpyTransport

        name = f'growspace_rig_{os.getpid()}_{secrets.token_hex(3)}'
        self._transport = RclpyTransport(name, self.namespace)
        self.link = ChamberLink(self._transport, with_state=False, liveness=liveness)
        self.link.connect(self.settings.step_timeout_s)

    def reset(self, reset_id: int, seed: int) -> Answer:
        reply = self.link.reset(reset_id, seed, self.settings.challenge, self.settings.setting,
                                self.settings.step_timeout_s)
        return _answer(reply)

    def step(self, reset_id: int, step_id: int, action: int) -> Answer:
        return _answer(self.link.step(reset_id, step_id, self.settings.step_timeout_s,
                                      action=action))

    def close(self) -> None:
        transport, self._transport, self.link = self._transport, None, None
        if transport is not None:
            transport.close()


def _answer(reply: Any) -> Answer:
    result = reply.result
    image = None if reply.image is None else np.array(convert.image_from_msg(reply.image))
    return Answer(str(result.info), float(result.reward), bool(result.terminated),
                  bool(result.truncated), int(result.step), image)


class SimChamber(_LinkChamber):
    """``sim_node`` started by the runner, recording into the run directory (split)."""

    def __init__(self, settings: RunSettings, recording: Path) -> None:
        super().__init__(settings, settings.namespace or
                         f'/growspace_rig_{os.getpid()}_{secrets.token_hex(3)}')
        self.recording = recording
        self.simulated = True
        self.node: Any = None

    def prepare(self) -> dict[int, list[RecordedStep]]:
        from growspace_sim.recording import repair, wait_until_free

        if not self.recording.is_dir():
            return {}
        # A node whose runner died stops by itself and finishes its file first.
        if not wait_until_free(self.recording, self.settings.step_timeout_s):
            raise RunnerError(f'{self.recording} is still being recorded by another '
                              f'process after {self.settings.step_timeout_s:g} s; is a '
                              f'runner of this run still going?')
        repair(self.recording)
        recorded = recorded_episodes(self.recording)
        if not recorded:
            # Nothing of an episode survived (a crash before its first chunk reached the disk):
            # sim_node cannot resume from it. Kept aside, never deleted; the journal's steps
            # are re-simulated into a new recording.
            os.replace(self.recording, self.recording.with_name(
                f'{self.recording.name}.unusable-{secrets.token_hex(3)}'))
        return recorded

    def start(self, resume: bool) -> None:
        from growspace_gym_bridge.errors import NodeDied
        from growspace_gym_bridge.process import NodeProcess
        from growspace_sim.ros import loopback

        loopback.confine()  # our own node and our side of it stay on loopback
        params: dict[str, Any] = {
            'challenge': self.settings.challenge, 'setting': self.settings.setting,
            'mode': 'lockstep', 'seed': self.settings.seed,
            'record_path': str(self.recording),
            'record_max_bytes': self.settings.record_max_bytes,
            'record_max_duration_s': float(self.settings.record_max_duration_s)}
        if resume and self.recording.is_dir():
            params['resume_path'] = str(self.recording)  # prepare() left its files readable
        if not (params['record_max_bytes'] or params['record_max_duration_s'] or
                'resume_path' in params):
            params['record_max_duration_s'] = 1e9  # always a split directory, never one file
        self.node = NodeProcess(self.namespace, params)

        def liveness(describe: Callable[[], str]) -> None:
            code = self.node.poll()
            if code is not None:
                raise NodeDied(self.namespace, code, self.node.stderr_tail(), describe())
        self._connect(liveness)

    def close(self) -> None:
        super().close()
        if self.node is not None:
            self.node.stop()  # SIGTERM: the node finishes its recording file


class AttachedChamber(_LinkChamber):
    """A running lockstep chamber (``sim_node``, or ``gantry_node`` with ``camera_node``).

    The runner cannot read its recording (the node writes it where it was told), so a resume
    goes on from the journal alone: a step in progress at the crash is resent with its own
    step_id, which a chamber that did it refuses as a duplicate (``Runner._step``). A chamber
    node that restarted meanwhile must continue the episode to answer it: ``sim_node`` and
    ``gantry_node`` with ``resume_path`` on their own recording (docs/hardware.md).
    """

    def prepare(self) -> dict[int, list[RecordedStep]]:
        return {}

    def start(self, resume: bool) -> None:
        from growspace_sim.ros import loopback

        loopback.confine()
        self._connect()


def make_chamber(rundir: RunDir) -> RigChamber:
    """The chamber of a run's settings."""
    if rundir.settings.chamber == 'sim':
        return SimChamber(rundir.settings, rundir.recording_path)
    return AttachedChamber(rundir.settings, rundir.settings.namespace)
