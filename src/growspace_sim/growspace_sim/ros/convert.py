"""Simulation state <-> ROS 2 messages: the only module that knows both the core and the msgs.

Messages are rosbags dataclasses of the types parsed from ``growspace_msgs`` (see
``growspace_sim.ros.types``); every adapter (rclpy and in-process node, recorder, replay)
builds and reads them here, so the topics carry the same bytes whichever way they were produced.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from growspace_sim.core import task as tasks
from growspace_sim.core.chamber import Chamber, StepOutcome
from growspace_sim.core.errors import CommandError
from growspace_sim.core.light import Light
from growspace_sim.ros import types

MODE_BEAM, MODE_SPOT, MODE_DISCRETE, MODE_CONTINUOUS = 0, 1, 2, 3
MAX_SEED = 2**63 - 1  # seeds travel as uint64; numpy takes any non-negative int


@functools.cache
def _cls(typename: str) -> type:
    """The message class of a type (cached: messages are built on every step)."""
    return types.msg_class(typename)


def stamp(ns: int) -> Any:
    """``builtin_interfaces/Time`` for a time in nanoseconds."""
    return _cls('builtin_interfaces/msg/Time')(sec=ns // 1_000_000_000,
                                               nanosec=ns % 1_000_000_000)


def header(ns: int, frame_id: str) -> Any:
    return _cls('std_msgs/msg/Header')(stamp=stamp(ns), frame_id=frame_id)


def to_ns(time: Any) -> int:
    """Nanoseconds of a ``builtin_interfaces/Time``."""
    return int(time.sec) * 1_000_000_000 + int(time.nanosec)


def image_msg(image: np.ndarray, stamp_ns: int, frame_id: str) -> Any:
    """``sensor_msgs/Image`` rgb8 of an (H, W, 3) uint8 observation."""
    height, width = image.shape[:2]
    return _cls(types.IMAGE)(
        header=header(stamp_ns, frame_id), height=height, width=width, encoding='rgb8',
        is_bigendian=0, step=width * 3, data=np.ascontiguousarray(image).reshape(-1))


def image_from_msg(msg: Any) -> np.ndarray:
    """The (H, W, 3) uint8 array of an rgb8 ``sensor_msgs/Image``.

    Raises:
        ValueError: if the encoding is not rgb8 or the sizes disagree.
    """
    if msg.encoding != 'rgb8' or msg.step != msg.width * 3 \
            or len(msg.data) != msg.height * msg.step:
        raise ValueError(f'expected an rgb8 image with step = 3 x width, got encoding '
                         f'{msg.encoding!r}, {msg.width}x{msg.height}, step {msg.step}, '
                         f'{len(msg.data)} B.')
    return np.asarray(msg.data, np.uint8).reshape(msg.height, msg.width, 3)


def plant_state_msg(chamber: Chamber, step_id: int, stamp_ns: int, frame_id: str) -> Any:
    """``growspace_msgs/PlantState`` of every plant in the chamber."""
    n = chamber.n_nodes
    pos = chamber.pos[:n]
    return _cls(types.PLANT_STATE)(
        header=header(stamp_ns, frame_id), step_id=step_id, step=chamber.steps,
        node_x=pos.real.copy(), node_z=pos.imag.copy(),
        parent=chamber.parent[:n].astype(np.int32), plant=chamber.plant[:n].astype(np.uint8),
        tips=chamber.tips().astype(np.uint32),
        branch_count=chamber.branch_counts().astype(np.uint32))


def step_result_msg(outcome: StepOutcome, *, step_id: int, reset_id: int, step: int,
                    stamp_ns: int, frame_id: str, info: str = '') -> Any:
    """``growspace_msgs/StepResult`` of a step (or of a reset, with step 0)."""
    return _cls(types.STEP_RESULT)(
        header=header(stamp_ns, frame_id), step_id=step_id, reset_id=reset_id, step=step,
        reward=outcome.reward, plant_rewards=np.asarray(outcome.plant_rewards, np.float64),
        terminated=False, truncated=outcome.truncated, success=outcome.success, info=info)


def light_msg(light: Light, step_id: int, stamp_ns: int, frame_id: str) -> Any:
    """The applied light as an absolute ``growspace_msgs/LightCommand`` (beam or spot mode)."""
    return _light_command(stamp_ns, frame_id, step_id, MODE_SPOT if light.spot else MODE_BEAM,
                          x=light.x, z=light.z, width=light.width, radius=light.radius)


def discrete_command_msg(action: int, step_id: int, stamp_ns: int, frame_id: str) -> Any:
    """A ``growspace_msgs/LightCommand`` carrying one discrete action (lockstep clients)."""
    return _light_command(stamp_ns, frame_id, step_id, MODE_DISCRETE, action=action)


def _light_command(stamp_ns: int, frame_id: str, step_id: int, mode: int, *, x: float = 0.0,
                   z: float = 0.0, width: float = 0.0, radius: float = 0.0,
                   action: int = 0) -> Any:
    # The class directly, every field given: types.new's generic defaults cost ~4 us a message.
    return _cls(types.LIGHT_COMMAND)(
        header=header(stamp_ns, frame_id), step_id=step_id, mode=mode, x=x, z=z, width=width,
        radius=radius, action=action, continuous=np.zeros(0, np.float32))


def clock_msg(stamp_ns: int) -> Any:
    return _cls(types.CLOCK)(clock=stamp(stamp_ns))


def apply_command(sim: Any, msg: Any) -> None:
    """Apply a ``LightCommand`` to a ``Simulation``'s light (not yet stepping).

    Raises:
        CommandError: naming the field, its value and what is allowed, for an unknown mode, an
            absolute mode that does not match the challenge's light, a non-finite coordinate,
            an action out of range or a continuous vector of the wrong size or range. The light
            is unchanged then.
    """
    spot = sim.chamber.light.spot
    mode = int(msg.mode)
    if mode == MODE_DISCRETE:  # the light module checks actions and coordinates
        sim.apply_discrete(int(msg.action))
    elif mode == MODE_CONTINUOUS:
        # NaN/inf in the float32 action are rejected by the light; numpy's warning is noise.
        with np.errstate(invalid='ignore', over='ignore'):
            sim.apply_continuous(np.asarray(msg.continuous, np.float64))
    elif mode in (MODE_BEAM, MODE_SPOT):
        if (mode == MODE_SPOT) != spot:
            _reject('mode', mode, f'{MODE_SPOT if spot else MODE_BEAM} (this challenge has a '
                    f'{"spotlight" if spot else "beam"}), {MODE_DISCRETE} or {MODE_CONTINUOUS}')
        light = sim.chamber.light
        sim.place_light(x=msg.x, z=msg.z if spot else light.z,
                        width=light.width if spot else msg.width,
                        radius=msg.radius if spot else light.radius)
    else:
        _reject('mode', mode, f'{MODE_BEAM} (beam), {MODE_SPOT} (spot), {MODE_DISCRETE} '
                f'(discrete action) or {MODE_CONTINUOUS} (continuous action)')


def reset_args(msg: Any) -> tuple[int | None, str | None, str | None]:
    """(seed or None, challenge or None, setting or None) of a ``ResetRequest``.

    Raises:
        CommandError: naming the field for a challenge that is not registered or loaded, or a
            seed too large (the setting is checked against the challenge by ``SimConfig``).
    """
    challenge = msg.challenge or None
    setting = msg.setting or None  # checked against the challenge's settings by SimConfig
    if challenge is not None and not tasks.known(challenge):
        # A message never makes the node import a module: module:attribute challenges are
        # loaded when the node starts (its challenge parameter), then a reset may name them.
        _reject('challenge', challenge, f'one of {tasks.names()} or empty (keep)')
    seed = int(msg.seed) if msg.has_seed else None
    if seed is not None and seed > MAX_SEED:
        _reject('seed', seed, f'an int in [0, {MAX_SEED}]')
    return seed, challenge, setting


def _reject(field: str, value: Any, allowed: str) -> None:
    raise CommandError(field, value, allowed)
