"""The gantry node's logic over the simulator's ``Transport``: topics in, moves out, safety.

Same topics and messages as ``sim_node`` (``growspace_sim.ros.interface``), in its namespace:

- in ``light/command`` (growspace_msgs/LightCommand): every mode; actions move the light by the
  simulator's own rules
- in ``reset`` (growspace_msgs/ResetRequest): places the light as the simulator would for that
  seed and challenge
- in ``gantry/estop`` (std_msgs/Empty topic and std_srvs/Trigger service): feed hold, lamp off,
  soft reset
- in ``gantry/unlock``, ``gantry/home`` (std_srvs/Trigger): a person's ``$X`` / ``$H``
- with ``resume_path``: the last episode of its recording goes on (``resume.py``)
- out ``chamber/config`` (std_msgs/String, latched JSON): the simulator's keys, and
  ``target``, the episode's target exactly as the camera is sent it (``target_payload``), so a
  recording holds it and never needs the layout run again
- out ``light/state`` (LightCommand): the light the controller REPORTS reaching
- out ``step_result`` (StepResult): once per reset and lockstep command, when it is done
- out ``gantry/status`` (DiagnosticArray): state, position, alarm, buffer, link (1 Hz, on change)
- with ``growth_s`` (lockstep): a step's growth period, lamp on at the target, between its move
  and its photo (``growth.py``); the lamp follows the photoperiod (``lights_on``/``lights_off``)
- with ``camera`` (lockstep): calls camera_node's ``camera/capture`` after each reached move and
  growth period, answers the step when it answers (``photo.py``); out ``camera/image_raw``,
  ``plant/state``, ``camera/photo`` (sensor_msgs/CompressedImage) and ``camera/measurement``,
  in the simulator's order around ``light/state``, all with the step's stamp, and the reward

The light model is a ``Simulation`` that is never stepped: its light moves by ``core.light``
(clamped inside the chamber exactly as in the simulator) and a reset places it with the task's
own layout, so an agent's action, a bag's command and a teleop key mean the same light on both.
A relative action starts from the light the machine reports (never from a target it may not
have reached), and a command that is refused changes nothing. The safety rules (which command
may move the machine, what every fault does, the watchdog, the e-stop latch) are ``safety.py``;
a command that cannot be reached is refused before anything is sent.
"""

from __future__ import annotations

from collections.abc import Callable
import dataclasses
import json
import secrets
import time
from typing import Any

import numpy as np

from growspace_gantry.calibration import Calibration, TargetError
from growspace_gantry.controller import GrblController, Log
from growspace_gantry.growth import StepTime
from growspace_gantry.photo import capture_request, outputs, Photographer, Shot
from growspace_gantry.record import NodeRecording
from growspace_gantry.resume import GantryResume, StepBase
from growspace_gantry.safety import Safety
from growspace_gantry.settings import GantryParams
from growspace_gantry.status import diagnostics, DIAGNOSTICS
from growspace_sim import __version__
from growspace_sim.core.chamber import StepOutcome
from growspace_sim.core.config import SimConfig
from growspace_sim.core.errors import CommandError
from growspace_sim.node.chamber_node import EPISODE_OVER, NOT_READY, Recorder, step_id_error
from growspace_sim.node.transport import Transport
from growspace_sim.ros import convert
from growspace_sim.ros import qos as ros_qos, types
from growspace_sim.ros.interface import (
    CAMERA_OUTPUTS, COMMAND_QOS, config_json, growspace_metadata, METADATA_NAME, OBSERVATION_QOS,
    target_payload, Topic)
from growspace_sim.simulation import Simulation

EMPTY = 'std_msgs/msg/Empty'
TRIGGER = 'std_srvs/srv/Trigger'
POLL_S = 0.01  # how often the controller's link is read [s]
STATUS_PERIOD_S = 1.0  # gantry/status at least this often [s]
GANTRY_METADATA = 'growspace_gantry'  # recording metadata: the rig and its calibration

INPUTS = (
    Topic('reset', 'reset', types.RESET_REQUEST, COMMAND_QOS),
    Topic('command', 'light/command', types.LIGHT_COMMAND, COMMAND_QOS),
    Topic('estop', 'gantry/estop', EMPTY, COMMAND_QOS),
)
OUTPUTS = (
    Topic('config', 'chamber/config', types.STRING, ros_qos.LATCHED),
    Topic('light', 'light/state', types.LIGHT_COMMAND, OBSERVATION_QOS),
    Topic('result', 'step_result', types.STEP_RESULT, OBSERVATION_QOS),
    Topic('status', 'gantry/status', DIAGNOSTICS, OBSERVATION_QOS),
)


class GantryNode:
    """One LED gantry on the chamber topics.

    Args:
        transport: the middleware (``RclpyTransport``; ``LocalTransport`` in tests).
        controller: the GRBL controller (not yet connected; ``poll`` connects it).
        cfg: the chamber configuration (challenge, light limits, chamber size).
        params: the node settings.
        recorder: receives every message's CDR bytes, or None.
        clock: monotonic time [s].
        wall_clock: UTC time [s since the epoch] (the growth period and the photoperiod).
        resume: go on with the last episode of a recording (``resume.py``), or None.
    """

    def __init__(self, transport: Transport, controller: GrblController, cfg: SimConfig,
                 params: GantryParams, recorder: Recorder | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 wall_clock: Callable[[], float] = time.time,
                 resume: GantryResume | None = None) -> None:
        self.transport = transport
        self.log = transport.logger
        self.controller = controller
        self.cal: Calibration = controller.cal
        self.params = params
        self.cfg = cfg
        self.clock = clock
        self.recording = NodeRecording(recorder, transport, self.log.warn)
        self.sim = Simulation(cfg)  # the light model: never stepped
        self.reset_id = 0
        self.last_step_id = 0
        self.steps = 0  # steps of this episode answered without an error (a failed one is
        # redone by the agent: counting it would skip its number; resume.py)
        self.config = ''  # the episode's chamber/config payload, also sent with each photo
        self.pending: tuple[int, int, float] | None = None  # (reset_id, step_id, deadline)
        self.safety = Safety(controller, Log(self.log.warn, self.log.info), self._fail_pending,
                             params.watchdog_s, clock())
        self._next_status = 0.0
        self._status_key: tuple = ()
        self._size_warned = False
        self.photo: Photographer | None = None
        self.step_time = StepTime(params.growth_s if params.mode == 'lockstep' else 0.0,
                                  params.photoperiod, wall_clock)
        camera = params.camera and params.mode == 'lockstep'
        self.outputs = (*OUTPUTS, *(CAMERA_OUTPUTS if camera else ()))
        self._pubs = {t.key: transport.publisher(t.typename, t.name, t.qos) for t in self.outputs}
        if camera:
            self.photo = Photographer(transport, controller, params.camera,
                                      params.capture_timeout_s, params.photo_settle_s,
                                      self._photographed)
        elif params.camera:
            self.log.warn('camera', f'gantry: camera = {params.camera!r} is used in lockstep '
                          f'mode only; in realtime camera_node photographs on its own timer')
        handlers = {'reset': self.on_reset, 'command': self.on_command,
                    'estop': lambda msg, cdr: self.estop('gantry/estop topic')}
        for t in INPUTS:
            transport.subscribe(t.typename, t.name, t.qos,
                                self.recording.received(t.key, handlers[t.key]))
        transport.serve(TRIGGER, 'gantry/estop', lambda req: self._trigger(
            self.estop('gantry/estop service')))
        transport.serve(TRIGGER, 'gantry/unlock', lambda req: self._trigger(
            self.safety.unlock(), 'unlocked (e-stop latch released, $X sent in alarm); nothing '
            'moves until a new command; re-home if the position is in doubt'))
        transport.serve(TRIGGER, 'gantry/home', lambda req: self._trigger(
            self.safety.home(), 'homing ($H) sent'))
        transport.create_timer(POLL_S, self.poll)
        seed = params.seed if params.seed >= 0 else secrets.randbits(63)
        self.base = StepBase()  # where a resumed or redone step's action starts
        if resume is not None:
            seed = self._resume(resume)
        self._start_recording(seed)
        self.sim.reset(seed=seed)
        if resume is not None and resume.light is not None:
            x, z, width, radius = resume.light
            self.sim.place_light(x=x, z=z, width=width, radius=radius)
            self.base.resume(resume.light)
        self._publish_config(seed)
        # The machine does not move at start-up: the first command or reset moves it.

    # --- inputs ----------------------------------------------------------------------------

    def on_command(self, msg: Any, cdr: bytes) -> None:
        """A LightCommand: move the model light by the simulator's rules, then the machine."""
        step_id = int(msg.step_id)
        lockstep = self.params.mode == 'lockstep'
        if lockstep:
            error = step_id_error(step_id, self.last_step_id, self.log)
            if error:
                self._result(step_id, self.reset_id, info=error)
                return
            self.last_step_id = step_id
            if self.steps >= self.cfg.episode_length:
                self._result(step_id, self.reset_id, info=EPISODE_OVER, truncated=True)
                return
        relative = int(msg.mode) in (convert.MODE_DISCRETE, convert.MODE_CONTINUOUS)
        # The first action after a resume, or the redo of a failed step: from the light the
        # last answered step reached, absolutely (not from where a failed move or homing left
        # it); after a resume even before the position is re-established (resume.py).
        recorded = relative and self.base.bypass
        reason = self.safety.refusal(relative and not recorded) or self.recording.stopped
        if reason:
            self._refused('command:refused', f'light/command: not sent: {reason}',
                          step_id if lockstep else None, f'error: {NOT_READY}: {reason}')
            return
        if lockstep and (self.pending or self.step_time.busy or self.photo and self.photo.busy):
            self._fail_pending(f'superseded by a newer command (step_id {step_id})')  # redone
        light = self.sim.chamber.light
        before = light.copy()
        try:
            base = self.base.base if relative else None
            if relative:  # from the light the machine reached, never from a target
                reached = self.cal.to_light(self.controller.position, light)
                x, z, width, radius = base or (reached.x, reached.z, reached.width,
                                               reached.radius)
                self.sim.place_light(x=x, z=z, width=width, radius=radius)
            convert.apply_command(self.sim, msg)
            target = self.cal.to_machine(self.sim.chamber.light)
        except (CommandError, TargetError) as e:
            # Nothing is sent and the model light stays as it was.
            self.sim.place_light(x=before.x, z=before.z, width=before.width,
                                 radius=before.radius)
            self._refused(f'command:{getattr(e, "field", "travel")}',
                          f'light/command: not sent to the machine: {e}',
                          step_id if lockstep else None, f'error: {e}')
            return
        self.base.take()
        self._move(target, step_id if lockstep else None, placing=not relative or recorded)

    def on_reset(self, msg: Any, cdr: bytes) -> None:
        """A ResetRequest: place the light as the simulator would, then move there."""
        reset_id = int(msg.reset_id)
        reason = self.safety.refusal(relative=False) or self.recording.stopped
        try:
            if reason:
                raise ValueError(f'{NOT_READY}: {reason}')
            seed, challenge, setting = convert.reset_args(msg)
            changes = {k: v for k, v in (('challenge', challenge), ('setting', setting)) if v}
            cfg = self.cfg.replace(**changes) if changes else self.cfg
            sim = self.sim.fork(cfg)  # kept only if accepted: a refused reset changes nothing
            sim.reset(seed=seed)
            target = self.cal.to_machine(sim.chamber.light)
        except (CommandError, TargetError, ValueError) as e:
            self.log.warn('reset', f'reset: rejected reset_id {reset_id}: {e}')
            self._result(0, reset_id, info=f'error: {e}')
            return
        self.sim, self.cfg = sim, cfg
        self.reset_id, self.last_step_id, self.steps = reset_id, 0, 0
        self._publish_config(seed)
        self._move(target, 0, placing=True)

    def estop(self, source: str) -> str:
        """Feed hold, lamp off, soft reset, latched until gantry/unlock. Returns '' (done)."""
        self.safety.estop(source)
        return ''

    # --- the loop --------------------------------------------------------------------------

    def poll(self) -> None:
        """Timer callback: run the controller, apply the safety rules, answer finished moves.

        Never raises: an unexpected error is an e-stop (the machine in an unknown state is
        stopped and latched until a person looks).
        """
        try:
            self._poll(self.clock())
        except Exception as e:  # noqa: BLE001 - a timer callback must leave the machine safe
            self.log.warn('internal', f'gantry: internal error in the poll loop: '
                          f'{type(e).__name__}: {e}')
            if not self.safety.estop_latched:
                try:
                    self.safety.estop(f'an internal error ({type(e).__name__})')
                except Exception:  # noqa: BLE001 - nothing more can be done here
                    pass

    def _poll(self, now: float) -> None:
        c, photo, grow = self.controller, self.photo, self.step_time
        if c.target is not None:  # lit only inside the photoperiod; a fault clears the target
            c.set_lamp(grow.lamp_s(self.params.lamp_power * self.cal.lamp_max_s))
        self.safety.tick(now, c.poll(now), photographing=grow.busy or (
            photo is not None and photo.busy))
        if self.pending is not None:
            reset_id, step_id, deadline = self.pending
            if c.reached():
                self.pending = None
                if not grow.start(reset_id, step_id):
                    self._answer(reset_id, step_id)
            elif c.phase != 'ready':
                self._fail_pending(c.failure or f'the controller is {c.state}')
            elif now > deadline:
                self.safety.fault(f'the move did not finish within move_timeout_s = '
                                  f'{self.params.move_timeout_s:g} s; holding, lamp off')
        elif grow.busy:
            if (grown := grow.poll()) is not None:
                self._answer(grown.reset_id, grown.step_id)
        elif photo is not None:
            photo.poll(now)  # the photo light, the service, the camera's answer or a timeout
        flush = getattr(self.log, 'flush', None)
        if flush is not None:
            flush()  # how many warnings the throttle kept back, once their period is over
        realtime_due = self.params.mode == 'realtime' and now >= self._next_status
        key = (c.state, c.alarm, c.phase, c.fault, self.safety.estop_latched,
               self.safety.position_known, photo is not None and photo.phase,
               c.photo_light_accepted, grow.phase())
        if key != self._status_key or now >= self._next_status:
            self._status_key = key
            self._next_status = now + (1.0 / self.params.status_hz if
                                       self.params.mode == 'realtime' else STATUS_PERIOD_S)
            self._publish('status', diagnostics(self))
            if realtime_due and c.position is not None:
                self._publish('light', self._reached_light(0, self.transport.now_ns()))

    def _move(self, target: dict[str, float], step_id: int | None, placing: bool) -> None:
        if self.pending is not None or self.step_time.busy or (self.photo is not None
                                                               and self.photo.busy):
            self._fail_pending(f'superseded by a newer command (step_id {step_id})')
        if self.cal.size is None and not self._size_warned:
            self._size_warned = True
            self.log.warn('size', f'gantry: the calibration has no size axis: the lamp lights a '
                          f'fixed {self.cal.fixed_size_m:g} m whatever width or radius is asked.')
        self.controller.goto(target)
        self.controller.set_lamp(self.step_time.lamp_s(self.params.lamp_power
                                                       * self.cal.lamp_max_s))
        self.safety.accepted(self.clock(), placing)
        if step_id is not None:
            self.pending = (self.reset_id, step_id, self.clock() + self.params.move_timeout_s)

    def _refused(self, key: str, text: str, step_id: int | None, info: str) -> None:
        """A command that is not sent: logged (throttled), answered in lockstep."""
        self.log.warn(key, text)
        if step_id is not None:
            self._result(step_id, self.reset_id, info=info)

    def _fail_pending(self, reason: str) -> None:
        """Answer the step in progress (a move, its growth period or its photo) as failed."""
        shot = self.photo.abandon() if self.photo is not None else None
        grown = self.step_time.abandon()
        if shot is not None or grown is not None:
            reset_id, step_id = (shot or grown).reset_id, (shot or grown).step_id
        elif self.pending is not None:
            reset_id, step_id, _ = self.pending
        else:
            return
        self.pending = None
        if step_id:
            self.base.failed()
        self.log.warn('move', f'gantry: step_id {step_id} failed: {reason}')
        self._result(step_id, reset_id, info=f'error: {reason}')

    # --- outputs ---------------------------------------------------------------------------

    def _answer(self, reset_id: int, step_id: int) -> None:
        """A reached move: the step's answer, or with a camera the photo that leads to it."""
        stamp = self.transport.now_ns()
        light = self._reached_light(step_id, stamp)
        if self.photo is not None:
            chamber = self.sim.chamber
            request = capture_request(stamp, step_id, self.steps + bool(step_id), self.config,
                                      light, self.cfg, chamber.target, chamber.target_mask,
                                      self.params.frame_id)
            self.photo.start(reset_id, step_id, stamp, light, request, self.clock())
            return
        self._publish('light', light)
        self.base.answered_at(light)
        self.steps += bool(step_id)
        truncated = self.steps >= self.cfg.episode_length
        self._result(step_id, reset_id, stamp=stamp, truncated=truncated)

    def _photographed(self, shot: Shot, response: Any, failure: str) -> None:
        """The camera answered (or did not in time): publish the step in the simulator's
        order, the reward only from a measured photo."""
        messages, outcome, failure = outputs(response, shot.light, shot.stamp, self.cfg, failure)
        for key, msg in messages:
            self._publish(key, msg)
        self.steps += bool(shot.step_id) and not failure
        self.base.failed() if failure and shot.step_id else self.base.answered_at(shot.light)
        truncated = self.steps >= self.cfg.episode_length
        if failure:
            self.log.warn('camera:step', f'gantry: step_id {shot.step_id}: no measurement '
                          f'from the camera: {failure}')
        self._result(shot.step_id, shot.reset_id, info=f'error: camera: {failure}'
                     if failure else '', stamp=shot.stamp, truncated=truncated,
                     outcome=outcome)

    def _reached_light(self, step_id: int, stamp: int) -> Any:
        position = self.controller.position
        light = self.cal.to_light(position, self.sim.chamber.light)
        return convert.light_msg(light, step_id, stamp, self.params.frame_id)

    def _result(self, step_id: int, reset_id: int, info: str = '', stamp: int | None = None,
                truncated: bool = False, outcome: StepOutcome | None = None) -> None:
        outcome = (outcome or StepOutcome(0.0, np.zeros(self.cfg.plant_count), False, False,
                                          0))._replace(truncated=truncated)
        self._publish('result', convert.step_result_msg(
            outcome, step_id=step_id, reset_id=reset_id, step=self.steps,
            stamp_ns=self.transport.now_ns() if stamp is None else stamp,
            frame_id=self.params.frame_id, info=info))

    def _publish_config(self, seed: int | None) -> None:
        """The new episode's chamber/config (its seed: None for an unseeded reset), kept to be
        sent with each of its photos: the camera and the recording hold the same payload."""
        p, chamber = self.params, self.sim.chamber
        self.config = config_json(self.cfg, seed, mode=p.mode, rate_hz=0.0, frame_id=p.frame_id,
                                  reset_id=self.reset_id, episode=self.sim.episode,
                                  digit=self.sim.digit, source='gantry',
                                  target=target_payload(chamber.target, chamber.target_mask))
        self._publish('config', types.new(types.STRING, data=self.config))

    @staticmethod
    def _trigger(error: str, done: str = 'done') -> Any:
        return types.new(f'{TRIGGER}_Response', success=not error, message=error or done)

    def _publish(self, key: str, msg: Any) -> None:
        if key == 'result' and self.recording.wants(key):  # on disk before anyone sees it
            self.recording.write(key, types.serialize(msg, types.STEP_RESULT), flush=True)
            self._pubs[key](msg)
            return
        self.recording.write(key, self._pubs[key](msg))

    # --- recording (the node's own run, in the simulator's format) -----------------------

    def _resume(self, point: GantryResume) -> int:
        """Take the recorded episode's identity (``resume.py``); returns its seed."""
        self.cfg, self.sim = point.cfg, Simulation(point.cfg)
        self.reset_id, self.last_step_id, self.steps = point.reset_id, point.last_step_id, \
            point.steps
        self.log.info(f'gantry: resumed episode reset_id {point.reset_id} after step '
                      f'{point.steps} (last step_id {point.last_step_id}'
                      + (', the episode was over' if point.over else '') + '); the next '
                      'relative action is placed absolutely from the recorded light')
        return point.seed

    def _start_recording(self, seed: int) -> None:
        namespace = self.transport.resolve('~').rsplit('/', 1)[0] or '/'
        self.recording.start((*INPUTS, *self.outputs), {
            METADATA_NAME: growspace_metadata(self.cfg, seed, namespace=namespace,
                                              frame_id=self.params.frame_id, rate_hz=0.0,
                                              lockstep=self.params.mode == 'lockstep'),
            GANTRY_METADATA: {  # with each step's growth rule
                'version': __version__, 'port': self.params.port, **self.params.step_time(),
                'calibration': json.dumps(dataclasses.asdict(self.cal), sort_keys=True)}})

    # --- shutdown --------------------------------------------------------------------------

    def close(self, timeout_s: float = 2.0) -> None:
        """Lamp off and the machine idle, then close the link and the recording. Idempotent.

        The lamp-off line is confirmed by the controller within ``timeout_s``, else a soft
        reset (which switches the spindle output off) makes sure.
        """
        c = self.controller
        if c.link is not None:
            c.safe_stop()
            deadline = self.clock() + timeout_s
            while self.clock() < deadline and c.ready and not c.lamp_confirmed_off():
                c.poll(self.clock())
                time.sleep(0.005)
            if c.link is not None and not c.lamp_confirmed_off():
                c.estop()
        c.close()
        try:
            self._fail_pending('the gantry node is shutting down')
        except Exception:  # noqa: BLE001 - a signal already shut the ROS context down
            self.pending = None
        self.recording.close()

