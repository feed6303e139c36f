"""What a chamber puts on the wire: its topics, their QoS and order, and how it describes itself.

One table for every producer and reader of chamber messages: ``ChamberNode`` subscribes and
publishes from it, ``recording`` and ``tools.record`` name their channels from it and ``replay``
finds a chamber's topics with it. The ``chamber/config`` payload and the recording's
``growspace`` metadata record are built here too, so that the node (on rclpy or in
process) is the only producer of both. Nothing here imports MCAP: a node that does not record
does not need it.

| topic | type | direction | QoS |
|---|---|---|---|
| ``reset`` | growspace_msgs/ResetRequest | in | reliable, keep_all |
| ``light/command`` | growspace_msgs/LightCommand | in | reliable, keep_all |
| ``chamber/config`` | std_msgs/String (JSON, ``config_json``) | out | reliable, depth 1, latched |
| ``/clock`` | rosgraph_msgs/Clock (sim time) | out | reliable, keep_last 1 |
| ``camera/image_raw`` | sensor_msgs/Image (rgb8) | out | reliable, keep_last 10 |
| ``plant/state`` | growspace_msgs/PlantState | out | reliable, keep_last 10 |
| ``light/state`` | growspace_msgs/LightCommand (applied light) | out | reliable, keep_last 10 |
| ``step_result`` | growspace_msgs/StepResult (published last) | out | reliable, keep_last 10 |

Names are relative to the chamber namespace; ``/clock`` is absolute.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from typing import Any, NamedTuple

import numpy as np

from growspace_sim import __version__

from growspace_sim.core.config import SimConfig
from growspace_sim.ros import qos as ros_qos, types

# keep_all + reliable: a flood makes the sender wait (flow control) instead of losing commands.
COMMAND_QOS = ros_qos.QosProfile(history='keep_all')
OBSERVATION_QOS = ros_qos.QosProfile(depth=10)
METADATA_NAME = 'growspace'  # name of the recording's metadata record (``growspace_metadata``)
FORMAT = 'growspace-recording/1'  # bump when the topics or the metadata keys change meaning
FRAME_CONVENTION = ('x right along the light rail from the left wall, z up from the floor, '
                    'y = z cross x (into the image); image row 0 = chamber top')


class Topic(NamedTuple):
    """One topic of the chamber."""

    key: str  # short name the code uses
    name: str  # relative to the chamber namespace (``/clock`` is absolute)
    typename: str
    qos: ros_qos.QosProfile  # what the node offers (outputs) or requests (inputs)


INPUTS = (
    Topic('reset', 'reset', types.RESET_REQUEST, COMMAND_QOS),
    Topic('command', 'light/command', types.LIGHT_COMMAND, COMMAND_QOS),
)
# In the order a reset publishes them; a step publishes the same without ``config``, so
# ``step_result`` always comes last and tells a client that the step is complete.
OUTPUTS = (
    Topic('config', 'chamber/config', types.STRING, ros_qos.LATCHED),
    Topic('clock', '/clock', types.CLOCK, ros_qos.CLOCK),
    Topic('image', 'camera/image_raw', types.IMAGE, OBSERVATION_QOS),
    Topic('plant', 'plant/state', types.PLANT_STATE, OBSERVATION_QOS),
    Topic('light', 'light/state', types.LIGHT_COMMAND, OBSERVATION_QOS),
    Topic('result', 'step_result', types.STEP_RESULT, OBSERVATION_QOS),
)
# A camera's outputs for a step (camera_node's own in realtime; the gantry's, from the camera's
# answer, in lockstep), in the step's order around light/state: image, plant, light, photo,
# measurement, then step_result.
CAMERA_OUTPUTS = (
    Topic('image', 'camera/image_raw', types.IMAGE, OBSERVATION_QOS),
    Topic('plant', 'plant/state', types.PLANT_STATE, OBSERVATION_QOS),
    Topic('photo', 'camera/photo', types.COMPRESSED_IMAGE, OBSERVATION_QOS),
    Topic('measurement', 'camera/measurement', types.CAMERA_MEASUREMENT, OBSERVATION_QOS),
)
TOPICS = INPUTS + OUTPUTS  # received messages are handled (and recorded) before the outputs
NAMES = {topic.key: topic.name for topic in TOPICS}  # key ('result') -> name ('step_result')


def config_dict(cfg: SimConfig) -> dict[str, Any]:
    """JSON-ready fields of a config (``SimConfig.from_dict`` reads it back exactly)."""
    values = dataclasses.asdict(cfg)
    values['digits'] = list(cfg.digits)
    return values


def config_json(cfg: SimConfig, seed: int | None, **extra: Any) -> str:
    """The ``chamber/config`` String payload: effective config, episode seed, version.

    Args:
        cfg: The effective configuration of the episode being started.
        seed: The seed this reset used, or None when the random stream continued.
        **extra: More JSON-ready keys (the node adds e.g. ``mode``, ``rate_hz``, ``reset_id``).

    Returns:
        Compact JSON with sorted keys (floats round-trip exactly).
    """
    payload = {'config': config_dict(cfg), 'seed': seed, 'version': __version__,
               'format': FORMAT, **extra}
    return json.dumps(payload, sort_keys=True, separators=(',', ':'))


def target_payload(point: complex | None, mask: np.ndarray | None) -> dict[str, Any]:
    """The ``target`` entry of a rig's ``chamber/config`` payload: the episode's target exactly
    as the gantry sends it to the camera (``growspace_msgs/srv/Capture``).

    Args:
        point: The point target (x + iz) [m] (``has_point_target``, ``target_x``, ``target_z``).
        mask: The (res, res) shape target (``target_mask``), or None for a point target.

    Returns:
        ``{"mask": [row, ...]}`` (one string of ``0``/``1`` per image row, row 0 = chamber top)
        for a shape target, else ``{"x": .., "z": ..}`` (floats round-trip exactly in JSON).
    """
    if mask is not None:
        return {'mask': [''.join('1' if v else '0' for v in row)
                         for row in np.asarray(mask, bool)]}
    return {'x': float(point.real), 'z': float(point.imag)}


def target_from_payload(value: Any) -> tuple[complex | None, np.ndarray | None]:
    """The point or the shape mask of a ``target`` entry (``target_payload``).

    Raises:
        ValueError: naming what is wrong with the entry.
    """
    if isinstance(value, dict) and set(value) == {'x', 'z'}:
        x, z = value['x'], value['z']
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
               for v in (x, z)):
            return complex(x, z), None
    elif isinstance(value, dict) and set(value) == {'mask'} and isinstance(value['mask'], list):
        rows = value['mask']
        if rows and all(isinstance(r, str) and len(r) == len(rows) and set(r) <= {'0', '1'}
                        for r in rows):
            return None, np.array([[c == '1' for c in row] for row in rows], bool)
    raise ValueError(f'target must be {{"x": <m>, "z": <m>}} (finite) or {{"mask": [<n> rows '
                     f'of <n> "0"/"1">]}}, got {json.dumps(value)[:120]}')


def growspace_metadata(cfg: SimConfig, seed: int | None, *, namespace: str, frame_id: str,
                       rate_hz: float, lockstep: bool, digit_source: str = 'auto',
                       digit_fingerprint: str = '') -> dict[str, str]:
    """The ``growspace`` metadata record: what replay and a hardware driver need to know.

    Args:
        cfg: The configuration the chamber started with.
        seed: Its first seed (None: unseeded, so the run cannot be re-simulated).
        namespace: The chamber namespace, e.g. ``/growspace``.
        frame_id: The chamber frame of every header, e.g. ``chamber``.
        rate_hz: Simulation steps per second of simulated time.
        lockstep: True if each LightCommand with a new step_id triggered exactly one step.
        digit_source: Where shape targets come from (``digits.load_digits``).
        digit_fingerprint: ``digit_fingerprint()`` of that set, for shape runs.

    Returns:
        String keys and values for ``McapRecorder.add_metadata(METADATA_NAME, ...)``.
    """
    return {
        'format': FORMAT,
        'version': __version__,
        'config': json.dumps(config_dict(cfg), sort_keys=True, separators=(',', ':')),
        'seed': '' if seed is None else str(seed),
        'namespace': namespace,
        'frame_id': frame_id,
        'rate_hz': repr(float(rate_hz)),
        'mode': 'lockstep' if lockstep else 'realtime',
        'digit_source': digit_source,
        'digit_fingerprint': digit_fingerprint,
        # Geometry for a hardware driver: REP-103 units, chamber frame described in the docs.
        'chamber_width_m': repr(cfg.chamber_width),
        'chamber_height_m': repr(cfg.chamber_height),
        'image_size_px': str(cfg.resolution),
        'pixel_size_m': repr(cfg.chamber_width / cfg.resolution),
        'light': 'spot' if cfg.uses_spotlight else 'beam',
        'frame_convention': FRAME_CONVENTION,
    }


def digit_fingerprint(sim: Any) -> str:
    """SHA-256 of a simulation's digit set (shape targets), or '' if it has none."""
    digit_set = getattr(sim, 'digit_set', None)
    if digit_set is None:
        return ''
    h = hashlib.sha256(digit_set.images.tobytes())
    h.update(digit_set.labels.tobytes())
    return h.hexdigest()
