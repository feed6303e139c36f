"""The chamber node's logic, written once against ``transport.Transport``.

Its topics, their QoS and publishing order are the table in ``ros.interface``. Lockstep: every
LightCommand whose step_id is above the last one processed since the latest reset is answered
by exactly one StepResult with that step_id (after one step, or without a step when the command
is invalid or the episode is over). Realtime: a timer steps at rate_hz with the latest command.
Sim time advances 1/rate_hz per step and per reset in both modes.

Recording (the ``recorder`` hook, ``growspace_sim.recording.McapRecorder``): the node writes
every message it receives and publishes, with the exact CDR bytes, stamped in sim time: the
outputs of a step or reset at its tick, a received message half a period before the tick it
causes (so time order is handling order). The ``growspace`` metadata record is written once, at
start. A failing recorder never stops the chamber: the node reports it once and records no more.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
import dataclasses
import math
import secrets
from typing import Any, Protocol

import numpy as np

from growspace_sim.core import task as tasks
from growspace_sim.core.chamber import StepOutcome
from growspace_sim.core.config import SimConfig
from growspace_sim.core.errors import CommandError
from growspace_sim.node.resume import ResumePoint
from growspace_sim.node.params import NodeParams, ParamError, as_values, build
from growspace_sim.node.transport import Transport
from growspace_sim.ros import convert
from growspace_sim.ros import qos as ros_qos, types
from growspace_sim.ros.interface import (
    COMMAND_QOS, INPUTS, METADATA_NAME, OBSERVATION_QOS, OUTPUTS, config_json,
    digit_fingerprint, growspace_metadata)
from growspace_sim.simulation import Simulation

__all__ = ['ChamberNode', 'COMMAND_QOS', 'EPISODE_OVER', 'INPUTS', 'NOT_READY', 'OBSERVATION_QOS',
           'OUTPUTS', 'Recorder']

EPISODE_OVER = 'episode over; send a reset'
NOT_READY = 'gantry not ready'  # a refusal worth waiting out: starting, in alarm or e-stop


def step_id_error(step_id: int, last_step_id: int, log: Any) -> str:
    """The lockstep rule for a command's step_id (ids rise within an episode, from 1).

    Returns:
        '' if the command may step, else the error text for its StepResult (also logged,
        throttled). A gap in the ids is allowed, with a warning.
    """
    if step_id == 0 or step_id <= last_step_id:
        # Answered, so a client never waits in vain.
        kind = 'zero' if step_id == 0 else 'stale'
        error = (f'step_id = {step_id} is not allowed in lockstep mode' if step_id == 0 else
                 f'step_id = {step_id} is a duplicate or late command') + (
            f'; expected step_id > {last_step_id} (the last processed since the reset)'
            f', or mode:=realtime.')
        log.warn(f'command:step_id:{kind}', f'light/command: dropped: {error}')
        return f'error: {error}'
    if step_id > last_step_id + 1 and last_step_id:
        log.warn('command:gap', f'light/command: step_ids {last_step_id + 1}..{step_id - 1} '
                 f'never arrived (lost, or skipped by the client); stepping {step_id}.')
    return ''


def _text(error: Exception) -> str:
    """How a rejected request is reported: a ValueError's own text names field and value."""
    return str(error) if isinstance(error, ValueError) else \
        f'reset failed: {type(error).__name__}: {error}'


class Recorder(Protocol):
    """What the node needs from a recorder (``growspace_sim.recording.McapRecorder``).

    A recorder that stopped for good (disk full, file gone) says why in ``error``.
    """

    error: str | None

    def add_channel(self, topic: str, typename: str, qos: ros_qos.QosProfile) -> int: ...

    def write_many(self, messages: Iterable[tuple[int, bytes, int, int]]) -> None: ...

    def add_metadata(self, name: str, data: dict[str, str]) -> None: ...

    def close(self) -> None: ...


class ChamberNode:
    """One simulated chamber on topics.

    Args:
        transport: the middleware.
        cfg: the chamber configuration.
        params: the node settings.
        recorder: receives every message's CDR bytes, or None.
        digit_source: where shape targets come from (see ``growspace_sim.digits``).
        on_reconfigure: called with the new configuration when a reset changed it (the
            rclpy node then shows the new challenge and setting in its parameters).
        resume: start where a recording ends (``replay.resume_point``) instead of with a
            new episode; its configuration replaces ``cfg``.
    """

    def __init__(self, transport: Transport, cfg: SimConfig, params: NodeParams | None = None,
                 recorder: Recorder | None = None, digit_source: str = 'auto',
                 on_reconfigure: Callable[[SimConfig], None] | None = None,
                 resume: ResumePoint | None = None) -> None:
        self.transport = transport
        self.log = transport.logger
        self.params = params or NodeParams()
        self.cfg = cfg
        self.digit_source = digit_source
        self.recorder = recorder
        self.on_reconfigure = on_reconfigure
        self.recording_error: str | None = None  # why the recorder stopped, once it did
        self.sim = Simulation(cfg, digit_source)
        self.sim_time_ns = 0
        self.last_step_id = 0
        self.reset_id = 0
        self.seed: int | None = None
        self.episode_over = False
        self.outcome: StepOutcome | None = None
        self.pending_cfg: SimConfig | None = None  # valid parameter changes, used at next reset
        self._latest: Any = None  # realtime: the command the next tick applies
        self._channels: dict[str, int] = {}
        self._batch: list[tuple[int, bytes, int, int]] = []  # this callback's messages, to record
        self._log_ns = 0  # recording time of what the node handles now (sim time) [ns]
        self._names = {key: transport.resolve(topic) for key, topic, _, _ in OUTPUTS}
        self._pubs = {key: transport.publisher(typename, topic, qos)
                      for key, topic, typename, qos in OUTPUTS}
        handlers = {'reset': self.on_reset, 'command': self.on_command}
        for key, topic, typename, qos in INPUTS:
            transport.subscribe(typename, topic, qos, handlers[key])
        transport.serve(types.RESET, 'reset', self.on_reset_service)
        self._timer = transport.create_timer(1.0 / self.params.rate_hz, self.tick) \
            if self.params.mode == 'realtime' else None
        if resume is not None:
            self._resume(resume)
            return
        seed = self.params.seed if self.params.seed >= 0 else secrets.randbits(63)
        self._start_recording(seed)
        self._reset(seed, cfg, reset_id=0)

    def _resume(self, point: ResumePoint) -> None:
        """Go on after a recording's last step, re-simulated bit for bit (``resume_point``).

        Nothing re-simulated is published or recorded again (a recording across the restart
        holds every step once); only the latched ``chamber/config``, unrecorded, for clients.
        """
        self.sim, self.cfg = point.sim, point.sim.cfg
        self.outcome, self.seed = point.outcome, point.seed
        self.reset_id, self.last_step_id = point.reset_id, point.last_step_id
        self.episode_over = point.episode_over
        self.sim_time_ns = self._log_ns = point.sim_time_ns
        self._start_recording(point.seed if point.seed is not None else -1)
        if self.on_reconfigure is not None:
            self.on_reconfigure(self.cfg)
        self._pubs['config'](types.new(types.STRING, data=self.config_payload(point.seed)))
        self.log.info(f'resumed episode {self.sim.episode} (reset_id {self.reset_id}) after '
                      f'step {self.sim.chamber.steps} (step_id {self.last_step_id}): the next '
                      f'command steps {self.sim.chamber.steps + 1}.')

    # --- inputs --------------------------------------------------------------------------

    def on_command(self, msg: Any, cdr: bytes) -> None:
        """A LightCommand arrived (transport callback)."""
        self._record_input('command', cdr)
        try:
            if self.params.mode == 'realtime':
                self._latest = msg  # last wins, whatever its mode; validated at the tick
            else:
                self._lockstep(msg)
        except Exception as e:  # noqa: BLE001 - keep the node alive, say why
            self.log.warn('command:internal', f'light/command: dropped, internal error '
                          f'{type(e).__name__}: {e}')
        finally:
            self._flush_records()

    def on_reset(self, msg: Any, cdr: bytes) -> None:
        """A ResetRequest arrived (transport callback)."""
        self._record_input('reset', cdr)
        try:
            reset_id = int(msg.reset_id)
            error = self.request_reset(msg, reset_id)
            if error is not None:
                key = error.field if isinstance(error, CommandError) else type(error).__name__
                self.log.warn(f'reset:{key}', f'reset: rejected reset_id {reset_id}: '
                              f'{_text(error).rstrip(".")}; the episode goes on unchanged.')
                self._publish_result(step_id=0, reset_id=reset_id,
                                     info=f'error: {_text(error)}')
        finally:
            self._flush_records()

    def on_reset_service(self, request: Any) -> Any:
        """The ``reset`` service (rclpy mode): same as the topic, the node picks the id."""
        reset_id = self.reset_id + 1
        error = self.request_reset(request, reset_id)
        return types.new(types.RESET_SRV_RESPONSE, success=error is None,
                         message='' if error is None else _text(error),
                         reset_id=0 if error else reset_id)

    def request_reset(self, msg: Any, reset_id: int) -> Exception | None:
        """Validate and apply a reset request (topic or service form).

        Returns:
            None on success, else the error: a ``CommandError`` for a bad field of the request,
            the ``SimConfig`` error for a configuration it cannot have, or whatever else failed
            (e.g. digits that cannot load). The state is unchanged then.
        """
        try:
            seed, challenge, setting = convert.reset_args(msg)
            cfg = self.pending_cfg or self.cfg
            changes = {k: v for k, v in (('challenge', challenge), ('setting', setting)) if v}
            if changes:
                cfg = cfg.replace(**changes)
            self._reset(seed, cfg, reset_id)
        except Exception as e:  # noqa: BLE001 - reported to the client, never raised
            return e
        return None

    def propose(self, values: dict[str, Any]) -> str | None:
        """Validate changed parameter values. Valid SimConfig changes apply at the next reset;
        ``rate_hz`` (realtime mode: the timer follows, and sim time per step) and
        ``auto_reset`` at once. The others are read-only (refused before this is called).

        Returns:
            None if accepted, else the reason (names the parameter, value and what is allowed).
        """
        challenge = values.get('challenge')
        if isinstance(challenge, str) and not tasks.known(challenge):  # imports only at start-up
            return (f'challenge must be one of {tasks.names()} (a module:attribute challenge is '
                    f'loaded at start-up only), got {challenge!r}.')
        current = as_values(self.pending_cfg or self.cfg, self.params)
        current.update(values)
        try:
            cfg, params = build(current)
        except ParamError as e:
            return str(e)
        self.pending_cfg = cfg if cfg != self.cfg else None
        if self._timer is not None and params.rate_hz != self.params.rate_hz:
            self._timer.set_period(1.0 / params.rate_hz)
        self.params = dataclasses.replace(self.params, rate_hz=params.rate_hz,
                                          auto_reset=params.auto_reset)
        return None

    # --- stepping ------------------------------------------------------------------------

    def _lockstep(self, msg: Any) -> None:
        step_id = int(msg.step_id)
        error = step_id_error(step_id, self.last_step_id, self.log)
        if error:
            self._publish_result(step_id, self.reset_id, info=error)
            return
        self.last_step_id = step_id
        if self.episode_over:
            self.log.warn('command:episode', f'light/command: step_id {step_id} not stepped: '
                          f'{EPISODE_OVER}.')
            self._publish_result(step_id, self.reset_id, info=EPISODE_OVER, truncated=True)
            return
        error = self._apply_or_warn(msg, f'step_id {step_id} not stepped')
        if error:
            self._publish_result(step_id, self.reset_id, info=error)
            return
        self._step(step_id)

    def tick(self) -> None:
        """Realtime mode: one timer period (a step, or an automatic reset after an episode)."""
        if self.episode_over:
            if self.params.auto_reset:
                self._reset(None, self.pending_cfg or self.cfg, self.reset_id)
            return
        msg, self._latest = self._latest, None
        info = '' if msg is None else self._apply_or_warn(msg, 'ignored, the light stays')
        self._step(0, info)

    def _apply_or_warn(self, msg: Any, consequence: str) -> str:
        """Apply a LightCommand; if it is bad, warn (throttled per field) and return the error
        text for the StepResult, else ''."""
        try:
            convert.apply_command(self.sim, msg)
        except CommandError as e:
            self.log.warn(f'command:{e.field}', f'light/command: {consequence}: {e}')
            return f'error: {e}'
        if int(msg.mode) in (convert.MODE_BEAM, convert.MODE_SPOT):
            light = self.sim.chamber.light
            for field in ('x', 'z', 'radius') if light.spot else ('x', 'width'):
                asked, applied = float(getattr(msg, field)), getattr(light, field)
                if asked != applied:
                    self.log.warn(f'command:clamped:{field}', f'light/command: {field} = '
                                  f"{asked!r} m is outside the light's limits; clamped to "
                                  f'{applied!r} m.')
        return ''

    def _step(self, step_id: int, info: str = '') -> None:
        self.outcome = self.sim.step()
        self.episode_over = self.outcome.truncated
        self.sim_time_ns += self.params.period_ns
        self._log_ns = self.sim_time_ns
        self._publish_observation(step_id, info)

    def _reset(self, seed: int | None, cfg: SimConfig, reset_id: int) -> None:
        """Begin an episode; raises ValueError before changing anything if ``cfg`` is bad."""
        if cfg != self.cfg:
            # Without a seed the random stream continues, so the episode stays reproducible.
            self.sim, self.cfg = self.sim.with_config(cfg), cfg
            if self.on_reconfigure is not None:
                self.on_reconfigure(cfg)
        self.pending_cfg = None
        self.outcome = self.sim.reset(seed=seed)
        self.seed = self.sim.seed
        self.reset_id = reset_id
        self.last_step_id = 0  # a reset is the lockstep sync point: ids count from 1 again
        self.episode_over = False
        self._latest = None
        self.sim_time_ns += self.params.period_ns
        self._log_ns = self.sim_time_ns
        self._publish_config(seed)
        self._publish_observation(0, '')

    # --- outputs -------------------------------------------------------------------------

    def config_payload(self, seed: int | None) -> str:
        """The ``chamber/config`` payload of the current episode.

        Args:
            seed: the seed of this reset; None when the random stream continued.
        """
        p = self.params
        return config_json(self.cfg, seed, mode=p.mode, rate_hz=p.rate_hz,
                           frame_id=p.frame_id, image_frame_id=p.image_frame_id,
                           digit_source=self.digit_source, reset_id=self.reset_id,
                           episode=self.sim.episode, digit=self.sim.digit)

    def _publish_config(self, seed: int | None) -> None:
        self._publish('config', types.new(types.STRING, data=self.config_payload(seed)))

    def _publish_observation(self, step_id: int, info: str) -> None:
        stamp, p = self.sim_time_ns, self.params
        chamber = self.sim.chamber
        # Outputs nobody reads (and no recorder wants) are not built: a lockstep RL client
        # reading images and results only saves three serialisations and writes per step.
        if self._wanted('clock'):
            self._publish('clock', convert.clock_msg(stamp))
        if self._wanted('image'):
            self._publish('image', convert.image_msg(self.sim.observe(), stamp,
                                                     p.image_frame_id))
        if self._wanted('plant'):
            self._publish('plant', convert.plant_state_msg(chamber, step_id, stamp, p.frame_id))
        if self._wanted('light'):
            self._publish('light', convert.light_msg(chamber.light, step_id, stamp, p.frame_id))
        self._publish_result(step_id, self.reset_id, info=info, outcome=self.outcome)

    def _wanted(self, key: str) -> bool:
        return key in self._channels or self.transport.has_subscribers(self._names[key])

    def _publish_result(self, step_id: int, reset_id: int, info: str,
                        outcome: StepOutcome | None = None, truncated: bool = False) -> None:
        """A StepResult, the last message of a tick; without ``outcome`` the reward is 0."""
        if outcome is None:
            n = self.cfg.plant_count
            outcome = StepOutcome(0.0, np.zeros(n), False, truncated or self.episode_over, 0)
        elif not math.isfinite(outcome.reward) or not np.isfinite(outcome.plant_rewards).all():
            # A broken task must not stop the chamber nor put NaN on the wire: the episode ends
            # here, the reason goes to the client in info, and rewards go out as 0.0.
            reason = (f'error: the {self.cfg.challenge} reward is not finite (reward '
                      f'{outcome.reward!r}, plant rewards {outcome.plant_rewards.tolist()}); '
                      f'the episode ends here with reward 0.0; send a reset.')
            self.log.warn('result:reward', f'step_result: {reason}')
            outcome = outcome._replace(reward=0.0, truncated=True, plant_rewards=np.nan_to_num(
                outcome.plant_rewards, nan=0.0, posinf=0.0, neginf=0.0))
            self.episode_over = True
            info = f'{info}; {reason}' if info else reason
        self._publish('result', convert.step_result_msg(
            outcome, step_id=step_id, reset_id=reset_id, step=self.sim.chamber.steps,
            stamp_ns=self.sim_time_ns, frame_id=self.params.frame_id, info=info))
        self._flush_records()

    def _publish(self, key: str, msg: Any) -> None:
        cdr = self._pubs[key](msg)
        channel = self._channels.get(key)
        if channel is not None:
            # One recorder call per callback (_flush_records, after its answer's last message):
            # half the recording cost was once the per-call locking and bookkeeping.
            self._batch.append((channel, cdr, self._log_ns, self._log_ns))

    # --- recording -----------------------------------------------------------------------

    def _start_recording(self, seed: int) -> None:
        """Register every topic as a channel and write the metadata record (once)."""
        recorder = self.recorder
        if recorder is None:
            return
        namespace = self.transport.resolve('~').rsplit('/', 1)[0] or '/'
        metadata = growspace_metadata(
            self.cfg, seed, namespace=namespace, frame_id=self.params.frame_id,
            rate_hz=self.params.rate_hz, lockstep=self.params.mode == 'lockstep',
            digit_source=self.digit_source, digit_fingerprint=digit_fingerprint(self.sim))
        try:
            for key, topic, typename, qos in (*INPUTS, *OUTPUTS):
                self._channels[key] = recorder.add_channel(self.transport.resolve(topic),
                                                           typename, qos)
            recorder.add_metadata(METADATA_NAME, metadata)
        except Exception as e:  # noqa: BLE001 - a recorder must never stop the chamber
            self._recording_failed(e)

    def _record_input(self, key: str, cdr: bytes) -> None:
        channel = self._channels.get(key)
        if channel is not None:
            # Half a period before the tick it causes; an answer without a step (a rejected
            # command or reset) is recorded at the same time, right after it.
            self._log_ns = self.sim_time_ns + self.params.period_ns // 2
            self._batch.append((channel, cdr, self._log_ns, self._log_ns))

    def _flush_records(self) -> None:
        """Hand this callback's messages to the recorder in one call (input, then outputs)."""
        if not self._batch:
            return
        batch, self._batch = self._batch, []
        try:
            self.recorder.write_many(batch)
        except Exception as e:  # noqa: BLE001 - a full disk must not stop the chamber
            self._recording_failed(e)

    def _recording_failed(self, error: Exception) -> None:
        reason = getattr(self.recorder, 'error', None)
        if reason is None:
            # A passing problem (this message only): say so, throttled, and go on recording.
            self.log.warn('recorder', f'recorder: a message was not recorded: '
                          f'{type(error).__name__}: {error}')
            return
        # The recorder stopped for good (disk full, file gone): say it once, stop recording
        # and keep the chamber running; complete chunks stay recoverable.
        self.recording_error = str(error)
        self._channels.clear()
        self._batch.clear()
        self.log.warn('recorder:stopped', f'recording stopped, the chamber goes on: {error}')

    def close(self) -> None:
        """Finish the recording (if any). Idempotent."""
        recorder, self.recorder = self.recorder, None
        self._channels.clear()
        if recorder is not None:
            try:
                recorder.close()
            except Exception as e:  # noqa: BLE001 - shutting down goes on
                self.log.warn('recorder', f'recorder close failed: {type(e).__name__}: {e}')
