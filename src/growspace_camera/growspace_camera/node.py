"""camera_node's logic over the simulator's ``Transport``: photos in, measurements out.

Topics and services, relative to the chamber namespace (beside gantry_node):

- service ``camera/capture`` (growspace_msgs/srv/Capture), both modes: one photo now, measured
  with the request's challenge, light and target; the answer holds the step's observation,
  plant state, photo and measurement, stamped with the request's stamp. The caller (the
  gantry, in lockstep) publishes them: see docs/architecture.md.
- out ``camera/status`` (diagnostic_msgs/DiagnosticArray): source, link, last measurement; 1 Hz
  and on change.
- out ``camera/segmentation`` (sensor_msgs/Image, rgb8): the photo with the mask, markers and
  tips, built only while someone subscribes.
- realtime mode only, a photo every ``1 / rate_hz`` s: in ``light/state`` and
  ``chamber/config`` (the reached light; the episode's challenge and seed, from which the
  target is laid out as the simulator does); out ``camera/image_raw``, ``plant/state``,
  ``camera/photo`` (sensor_msgs/CompressedImage) and ``camera/measurement``.

Callbacks never raise: a photo that cannot be read is a measurement with ``ok`` false and the
reason, a lost camera is a status and a retry with back-off.
"""

from __future__ import annotations

from collections.abc import Callable
import time
from typing import Any

import cv2

from growspace_camera import messages as wire
from growspace_camera.capture import Camera, Frame, Shot
from growspace_camera.errors import BAD_INPUT, CameraError, NO_PHOTO
from growspace_camera.measure import Target
from growspace_camera.pipeline import Measurement, overlay, Pipeline
from growspace_camera.settings import CameraParams
from growspace_sim.core.config import SimConfig
from growspace_sim.node.transport import Transport
from growspace_sim.ros import convert, qos as ros_qos, types
from growspace_sim.ros.interface import CAMERA_OUTPUTS, OBSERVATION_QOS, Topic
from growspace_sim.simulation import Simulation

POLL_S = 0.5  # how often a lost source is looked after [s]
STATUS_PERIOD_S = 1.0

OUTPUTS = (
    Topic('status', 'camera/status', wire.DIAGNOSTICS, OBSERVATION_QOS),
    Topic('segmentation', 'camera/segmentation', types.IMAGE, OBSERVATION_QOS),
)
REALTIME_OUTPUTS = CAMERA_OUTPUTS  # in the order a lockstep caller publishes them too
REALTIME_INPUTS = (
    Topic('light', 'light/state', types.LIGHT_COMMAND, OBSERVATION_QOS),
    Topic('config', 'chamber/config', types.STRING, ros_qos.LATCHED),
)


class CameraNode:
    """The chamber's camera on a transport.

    Args:
        transport: The middleware (``RclpyTransport``; ``LocalTransport`` in tests).
        camera: The photo source, kept open.
        pipeline: Measures photos.
        cfg: The configuration to assume until a chamber/config or a request says otherwise.
        params: The node settings.
        clock: Monotonic time [s].
    """

    def __init__(self, transport: Transport, camera: Camera, pipeline: Pipeline,
                 cfg: SimConfig, params: CameraParams,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.transport, self.log = transport, transport.logger
        self.camera, self.pipeline, self.params, self.clock = camera, pipeline, params, clock
        self.last: Measurement | None = None
        self.episode = 0  # resets seen (the twin source starts a new plant at each)
        self._status_key: tuple = ()
        self._next_status = 0.0
        self._pubs = {t.key: transport.publisher(t.typename, t.name, t.qos) for t in OUTPUTS}
        transport.serve(wire.CAPTURE, 'camera/capture', self.on_capture)
        transport.create_timer(POLL_S, self.poll)
        self.model: Simulation | None = None  # realtime: the episode's layout (target, light)
        self.seed: int | None = None
        self.steps = 0
        if params.mode == 'realtime':
            self._pubs.update({t.key: transport.publisher(t.typename, t.name, t.qos)
                               for t in REALTIME_OUTPUTS})
            handlers = {'light': self.on_light, 'config': self.on_config}
            for t in REALTIME_INPUTS:
                transport.subscribe(t.typename, t.name, t.qos, handlers[t.key])
            self._layout(cfg, params.seed if params.seed >= 0 else None)
            transport.create_timer(1.0 / params.rate_hz, self.tick)

    # --- lockstep: the capture service ------------------------------------------------------

    def on_capture(self, req: Any) -> Any:
        """One photo for a step: measured with the request's challenge, light and target."""
        stamp = convert.to_ns(req.header.stamp)
        step_id, step = int(req.step_id), int(req.step)
        try:
            cfg, seed = wire.parse_config(req.config)
            light = wire.light_from_msg(req.light)
            target = wire.target_from_request(req, cfg)
        except CameraError as e:
            self.log.warn(f'capture:{e.code}', f'camera/capture: refused: {e}')
            return self._response(Measurement(ok=False, error=e), None, stamp, step_id)
        if step == 0:
            self.episode += 1
        frame, m = self._photo(Shot(cfg, light, step, seed, self.episode), cfg, light, target,
                               step)
        return self._response(m, frame, stamp, step_id)

    # --- realtime: a photo on a timer ----------------------------------------------------

    def on_light(self, msg: Any, cdr: bytes) -> None:
        if self.model is None:
            return
        try:
            light = wire.light_from_msg(msg)
        except CameraError as e:
            self.log.warn('light', f'light/state: ignored: {e}')
            return
        self.model.place_light(light.x, light.z, light.width, light.radius)

    def on_config(self, msg: Any, cdr: bytes) -> None:
        try:
            cfg, seed = wire.parse_config(msg.data)
        except CameraError as e:
            self.log.warn('config', f'chamber/config: ignored: {e}')
            return
        self._layout(cfg, seed)

    def tick(self) -> None:
        """Realtime: take, measure and publish one photo."""
        model = self.model
        stamp = self.transport.now_ns()
        if model is None:
            return
        self.steps += 1
        cfg, light = model.cfg, model.chamber.light.copy()
        if self.seed is None:
            m = Measurement(ok=False, error=CameraError(
                BAD_INPUT, "the episode's target is unknown: chamber/config carried no seed "
                "(a continued random stream); reset with a seed"))
            frame = self._capture(Shot(cfg, light, self.steps, None, self.episode))
        else:
            frame, m = self._photo(Shot(cfg, light, self.steps, self.seed, self.episode), cfg,
                                   light, Target(model.chamber.target,
                                                 model.chamber.target_mask), self.steps)
        p = self.params
        self._pubs['image'](wire.observation_msg(m, stamp, p.image_frame_id))
        self._pubs['plant'](wire.plant_msg(m, stamp, 0, p.frame_id))
        self._pubs['photo'](wire.photo_msg(self._jpeg(frame), stamp, p.photo_frame_id))
        self._pubs['measurement'](wire.measurement_msg(m, stamp, 0, p.frame_id,
                                                       p.pixel_size_m))

    def _layout(self, cfg: SimConfig, seed: int | None) -> None:
        """The episode's target and starting light, laid out by the task as the simulator
        does (only with a seed: a continued stream cannot be followed)."""
        try:
            model = Simulation(cfg)
            model.reset(seed=seed if seed is not None else 0)
        except (ValueError, FileNotFoundError) as e:
            self.log.warn('config', f'chamber/config: cannot lay out {cfg.challenge}: {e}')
            return
        self.model, self.seed, self.steps = model, seed, 0
        self.episode += 1

    # --- both ----------------------------------------------------------------------------

    def poll(self) -> None:
        """Timer: look after a lost source, publish the status when due or changed."""
        self.camera.poll()
        now = self.clock()
        last = self.last
        key = (self.camera.online, self.camera.failure,
               None if last is None else (last.ok, last.error and last.error.code,
                                          last.confidence.fit_held))
        if key != self._status_key or now >= self._next_status:
            self._status_key, self._next_status = key, now + STATUS_PERIOD_S
            self._pubs['status'](self._diagnostics())

    def _capture(self, shot: Shot) -> Frame | None:
        return self.camera.read(shot)

    def _photo(self, shot: Shot, cfg: SimConfig, light: Any, target: Target,
               step: int) -> tuple[Frame | None, Measurement]:
        frame = self._capture(shot)
        if frame is None:
            retry = f'; next try in {self.camera.retry_in_s:.1f} s' if not self.camera.ended \
                else ''
            m = Measurement(ok=False, error=CameraError(
                NO_PHOTO, (self.camera.failure or f'{self.camera.source.name}: no frame')
                + retry))
        else:
            m = self.pipeline.measure(frame.bgr, cfg, light, target, step)
        if not m.ok:
            self.log.warn(f'measure:{m.error.code}', f'camera: photo not measured: {m.error}')
        self.last = m
        if frame is not None and self.transport.has_subscribers('camera/segmentation'):
            picture = overlay(frame.bgr, m, self.params.segmentation_scale)
            self._pubs['segmentation'](convert.image_msg(
                cv2.cvtColor(picture, cv2.COLOR_BGR2RGB), self.transport.now_ns(),
                self.params.photo_frame_id))
        self.poll()
        return frame, m

    def _response(self, m: Measurement, frame: Frame | None, stamp: int, step_id: int) -> Any:
        p = self.params
        return types.new(
            f'{wire.CAPTURE}_Response', observation=wire.observation_msg(m, stamp,
                                                                         p.image_frame_id),
            plant=wire.plant_msg(m, stamp, step_id, p.frame_id),
            photo=wire.photo_msg(self._jpeg(frame), stamp, p.photo_frame_id),
            measurement=wire.measurement_msg(m, stamp, step_id, p.frame_id, p.pixel_size_m))

    def _jpeg(self, frame: Frame | None) -> bytes | None:
        if frame is None:
            return None
        return frame.jpeg or wire.jpeg_of(frame.bgr, self.params.jpeg_quality)

    def _diagnostics(self) -> Any:
        c, last = self.camera, self.last
        if not c.online:
            level, message = 2, f'offline: {c.failure}'
        elif last is not None and not last.ok:
            level, message = 1, f'last photo not measured: {last.error}'
        elif last is not None and last.confidence.fit_held:
            level, message = 1, 'markers hidden: holding the last plane fit'
        else:
            level, message = 0, 'ok'
        values = {'source': c.source.name, 'online': str(c.online).lower(),
                  'failure': c.failure, 'retry_in_s': f'{c.retry_in_s:.1f}',
                  'frames': str(c.frames), **{f'accepted_{k}': v for k, v in c.accepted.items()}}
        if last is not None:
            conf = last.confidence
            values.update({
                'last_ok': str(last.ok).lower(),
                'last_error': '' if last.error is None else str(last.error),
                'markers_seen': ' '.join(str(i) for i in conf.markers_seen),
                'fit_held': str(conf.fit_held).lower(), 'fit_age': str(conf.fit_age),
                'plant_pixels': str(conf.plant_pixels), 'tips': str(conf.tips),
                'unexplained': f'{conf.unexplained:.3f}', 'loops': str(conf.loops),
                'processing_ms': f'{last.timings_ms.get("total", 0.0):.1f}'})
        kv = [types.new('diagnostic_msgs/msg/KeyValue', key=k, value=v)
              for k, v in values.items()]
        status = types.new('diagnostic_msgs/msg/DiagnosticStatus', level=level,
                           name=f'{self.transport.resolve("~")}: camera', message=message,
                           hardware_id=c.source.name, values=kv)
        return types.new(wire.DIAGNOSTICS, header=convert.header(self.transport.now_ns(),
                                                                 self.params.frame_id),
                         status=[status])

    def close(self) -> None:
        """Release the camera. Idempotent."""
        self.camera.close()
