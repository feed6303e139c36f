"""A measurement <-> ROS messages (rosbags classes of our codec, as the whole project uses).

The capture request carries the step's context (challenge, reached light, target); the
response carries the observation, the plant state, the photo and the measurement, all with
the request's stamp. Request fields are checked here: bad ones are a ``CameraError``
(``BAD_INPUT``) naming the field and the value, never an exception out of a callback.
"""

from __future__ import annotations

import functools
import json
import math
from typing import Any

import cv2
import numpy as np

from growspace_camera.errors import BAD_INPUT, CameraError
from growspace_camera.measure import Target
from growspace_camera.pipeline import Measurement
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import Light
from growspace_sim.ros import convert, types

CAPTURE, MEASUREMENT = types.CAPTURE, types.CAMERA_MEASUREMENT
COMPRESSED, DIAGNOSTICS = types.COMPRESSED_IMAGE, types.DIAGNOSTICS


@functools.lru_cache(maxsize=8)
def parse_config(text: str) -> tuple[SimConfig, int | None]:
    """The SimConfig and seed of a ``chamber/config`` payload (JSON with a ``config`` key).

    Raises:
        CameraError: ``BAD_INPUT`` naming what is wrong with it.
    """
    try:
        payload = json.loads(text)
        cfg = SimConfig.from_dict(payload['config'])
    except (ValueError, KeyError, TypeError) as e:
        raise CameraError(BAD_INPUT, f'config must be a chamber/config JSON payload with a '
                          f'valid "config": {e}') from None
    seed = payload.get('seed')
    return cfg, seed if isinstance(seed, int) and not isinstance(seed, bool) else None


def light_from_msg(msg: Any) -> Light:
    """The reached light of a LightCommand in MODE_BEAM or MODE_SPOT.

    Raises:
        CameraError: ``BAD_INPUT`` for another mode or a non-finite field.
    """
    mode = int(msg.mode)
    if mode not in (convert.MODE_BEAM, convert.MODE_SPOT):
        raise CameraError(BAD_INPUT, f'light.mode must be {convert.MODE_BEAM} (beam) or '
                          f'{convert.MODE_SPOT} (spot): the light as reached, got {mode}')
    values = {'x': msg.x, 'z': msg.z, 'width': msg.width, 'radius': msg.radius}
    for name, value in values.items():
        if not math.isfinite(value):
            raise CameraError(BAD_INPUT, f'light.{name} must be finite, got {value}')
    return Light(mode == convert.MODE_SPOT, float(msg.x), float(msg.z), float(msg.width),
                 float(msg.radius))


def target_from_request(req: Any, cfg: SimConfig) -> Target:
    """The episode's target the request carries.

    Raises:
        CameraError: ``BAD_INPUT`` for a target that does not fit the challenge.
    """
    if cfg.task.digits is None:
        if not req.has_point_target:
            raise CameraError(BAD_INPUT, f'the {cfg.challenge} challenge needs a point target '
                              f'(has_point_target = true)')
        target = Target(point=complex(req.target_x, req.target_z))
    else:
        res = cfg.resolution
        mask = np.asarray(req.target_mask, np.uint8)
        if mask.size != res * res:
            raise CameraError(BAD_INPUT, f'target_mask must have {res} x {res} = {res * res} '
                              f'values for {cfg.challenge}, got {mask.size}')
        target = Target(mask=mask.reshape(res, res) > 0)
    target.check(cfg)
    return target


def capture_request(cfg_json: str, light: Light, stamp_ns: int, step_id: int, step: int,
                    target: Target, frame_id: str = 'chamber') -> Any:
    """A Capture request (what the gantry will send; tests and tools use it too)."""
    point = target.point
    mask = np.zeros(0, np.uint8) if target.mask is None else \
        target.mask.astype(np.uint8).reshape(-1)
    return types.new(f'{CAPTURE}_Request', header=convert.header(stamp_ns, frame_id),
                     step_id=step_id, step=step, config=cfg_json,
                     light=convert.light_msg(light, step_id, stamp_ns, frame_id),
                     has_point_target=point is not None,
                     target_x=0.0 if point is None else point.real,
                     target_z=0.0 if point is None else point.imag, target_mask=mask)


def measurement_msg(m: Measurement, stamp_ns: int, step_id: int, frame_id: str,
                    pixel_size_m: float) -> Any:
    """The ``CameraMeasurement`` of a measurement (numbers zeroed when it is not ok)."""
    c = m.confidence
    error = m.error
    return types.new(
        MEASUREMENT, header=convert.header(stamp_ns, frame_id), step_id=step_id, ok=m.ok,
        error_code='' if error is None else error.code,
        error='' if error is None else error.message,
        reward=m.reward if m.ok else 0.0,
        plant_rewards=np.asarray(m.plant_rewards if m.ok else (), np.float64),
        success=bool(m.success and m.ok),
        markers_seen=np.asarray(c.markers_seen, np.uint8), fit_held=c.fit_held,
        fit_age=c.fit_age, fit_error_m=_finite(c.fit_error_m),
        exposure_mean=_finite(c.exposure_mean), saturated=_finite(c.saturated),
        threshold=_finite(c.threshold), contrast=_finite(c.contrast),
        plant_pixels=c.plant_pixels, specks=c.specks,
        skeleton_pixels=np.asarray(c.skeleton_px, np.uint32),
        unattached_pixels=c.unattached_px, tips=c.tips, tips_pruned=c.tips_pruned,
        leaves=c.leaves,
        pixel_size_m=pixel_size_m, processing_s=m.timings_ms.get('total', 0.0) / 1000.0)


def plant_msg(m: Measurement, stamp_ns: int, step_id: int, frame_id: str) -> Any:
    """The measured ``PlantState`` (no nodes when the photo was not measured)."""
    if not m.ok or m.tree is None or m.state is None:
        return types.new(types.PLANT_STATE, header=convert.header(stamp_ns, frame_id),
                         step_id=step_id)
    tree = m.tree
    return types.new(
        types.PLANT_STATE, header=convert.header(stamp_ns, frame_id), step_id=step_id,
        step=m.state.steps, node_x=tree.nodes[:, 0].copy(), node_z=tree.nodes[:, 1].copy(),
        parent=tree.parent.astype(np.int32), plant=tree.plant.astype(np.uint8),
        tips=tree.tips.astype(np.uint32), branch_count=m.state.branch_counts.astype(np.uint32))


def observation_msg(m: Measurement, stamp_ns: int, frame_id: str) -> Any:
    """The rgb8 observation (an empty image when the photo was not measured)."""
    if not m.ok or m.observation is None:
        return types.new(types.IMAGE, header=convert.header(stamp_ns, frame_id),
                         encoding='rgb8')
    return convert.image_msg(m.observation, stamp_ns, frame_id)


def photo_msg(jpeg: bytes | None, stamp_ns: int, frame_id: str) -> Any:
    """``sensor_msgs/CompressedImage`` of a photo's JPEG bytes (empty when none)."""
    return types.new(COMPRESSED, header=convert.header(stamp_ns, frame_id), format='jpeg',
                     data=np.frombuffer(jpeg or b'', np.uint8))


def jpeg_of(bgr: np.ndarray, quality: int) -> bytes:
    """JPEG bytes of a BGR photo."""
    ok, data = cv2.imencode('.jpg', bgr, (cv2.IMWRITE_JPEG_QUALITY, quality))
    return data.tobytes() if ok else b''


def _finite(value: float) -> float:
    return float(value) if math.isfinite(value) else 0.0
