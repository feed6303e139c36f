"""A rig's recording made here: what gantry_node records in lockstep with camera_node, built from
the photo twin and the real message classes, with growspace_sim.recording's writer.

Per reached move, with the step's stamp and in the gantry's order: ``camera/image_raw`` and
``plant/state`` (from a measured photo only), ``light/state``, ``camera/photo``,
``camera/measurement``, ``step_result`` (``info = "error: camera: <code>: <why>"`` when the photo
was not measured); ``chamber/config`` at start-up (``reset_id`` 0) and at each reset it takes,
with the episode's ``target`` as the camera is sent it; ``reset`` and ``light/command`` as
received. A reset the gantry refuses (``Refused``: its light out of the machine's travel) is
answered with an error step_result and no ``chamber/config``, and changes nothing, as
gantry_node's ``on_reset`` does; written as before the gantry recorded its target
(``target=False``), it has drawn from the random stream, as the gantry then did. The camera
answers through camera_node's own capture service (``FakeTransport``), asked with the
gantry's own payload.
"""

from __future__ import annotations

from dataclasses import dataclass
import json
from pathlib import Path

import numpy as np

from growspace_camera import messages as wire
from growspace_gantry.photo import capture_request as gantry_capture
from growspace_camera.main import build
from growspace_camera.settings import CameraParams
from growspace_sim.core.chamber import StepOutcome
from growspace_sim.core.config import SimConfig
from growspace_sim.node.fake import FakeTransport
from growspace_sim.node.params import as_values
from growspace_sim.recording import McapRecorder
from growspace_sim.ros import convert, types
from growspace_sim.ros.interface import (
    COMMAND_QOS, config_json, growspace_metadata, METADATA_NAME, OBSERVATION_QOS,
    target_payload)
from growspace_sim.ros.qos import LATCHED
from growspace_sim.simulation import Simulation

NS = '/growspace'
T0 = 1_700_000_000_000_000_000
STARTUP_SEED = 0  # the gantry's seed parameter: its start-up layout (no move, no photo)
TOPICS = {  # relative name -> (type, QoS), as gantry_node registers them
    'reset': (types.RESET_REQUEST, COMMAND_QOS),
    'light/command': (types.LIGHT_COMMAND, COMMAND_QOS),
    'chamber/config': (types.STRING, LATCHED),
    'camera/image_raw': (types.IMAGE, OBSERVATION_QOS),
    'plant/state': (types.PLANT_STATE, OBSERVATION_QOS),
    'light/state': (types.LIGHT_COMMAND, OBSERVATION_QOS),
    'camera/photo': (wire.COMPRESSED, OBSERVATION_QOS),
    'camera/measurement': (wire.MEASUREMENT, OBSERVATION_QOS),
    'step_result': (types.STEP_RESULT, OBSERVATION_QOS),
}


@dataclass(frozen=True)
class Refused:
    """A reset the gantry lays out and then refuses (seed None: unseeded)."""

    seed: int | None = None


def payload(world: Simulation, seed: int | None, reset_id: int) -> str:
    """The gantry's ``chamber/config`` payload (``GantryNode._config_payload``)."""
    c = world.chamber
    return config_json(world.cfg, seed, mode='lockstep', rate_hz=0.0, frame_id='chamber',
                       reset_id=reset_id, episode=world.episode, digit=world.digit,
                       source='gantry', target=target_payload(c.target, c.target_mask))


def rig_recording(path: Path, episodes: list[int | None | Refused], steps: int, *,
                  challenge: str = 'control', chunk_size: int = 1024 * 1024,
                  target: bool = True, **camera: object) -> Path:
    """Record oracle episodes on a twin rig (seed None: an unseeded reset).

    Args:
        path: The .mcap to write.
        episodes: One seed per reset (``Refused``: a reset the gantry refuses).
        steps: Steps per episode after its reset.
        challenge: The challenge.
        chunk_size: The recorder's chunk size.
        target: False: as gantry_node wrote before it recorded the target (``chamber/config``
            without it, and a refused reset that had drawn from the random stream).
        camera: camera_node parameters (e.g. ``min_greenness=0.9`` for a bad threshold).
    """
    transport = FakeTransport('growspace_camera', NS)
    build(transport, as_values(SimConfig(), CameraParams(source='twin', twin_seed=5, **camera)))
    capture = transport.services['camera/capture']
    cfg = SimConfig(challenge=challenge)
    world = Simulation(cfg)  # the plant the twin photographs, and the gantry's layout of it
    oracle = cfg.task.oracle()
    clock = iter(range(T0, T0 + 10**12, 10**7))
    # No timed flush: the chunks' layout depends on the messages only, not on this machine's load.
    with McapRecorder(path, chunk_size=chunk_size, flush_period_s=3600.0) as rec:
        channels = {rel: rec.add_channel(f'{NS}/{rel}', t, q) for rel, (t, q) in TOPICS.items()}
        rec.add_metadata(METADATA_NAME, growspace_metadata(
            cfg, STARTUP_SEED, namespace=NS, frame_id='chamber', rate_hz=0.0, lockstep=True))

        def write(rel: str, msg: object, t: int) -> None:  # a step's outputs: one callback
            rec.write(channels[rel], types.serialize(msg, TOPICS[rel][0]), t, t)

        def config(seed: int | None, reset_id: int, t: int) -> None:
            text = payload(world, seed, reset_id)
            if not target:
                text = json.dumps({k: v for k, v in json.loads(text).items() if k != 'target'},
                                  sort_keys=True, separators=(',', ':'))
            write('chamber/config', types.new(types.STRING, data=text), t)

        world.reset(seed=STARTUP_SEED)
        config(STARTUP_SEED, 0, next(clock))
        reset_id = 0
        for reset_id, seed in enumerate(episodes, start=1):
            refused = isinstance(seed, Refused)
            seed = seed.seed if refused else seed
            stamp = next(clock)
            write('reset', types.new(types.RESET_REQUEST, header=convert.header(stamp, ''),
                                     reset_id=reset_id, has_seed=seed is not None,
                                     seed=seed or 0), stamp)
            if not refused or not target:  # the gantry of then laid it out before refusing
                world.reset(seed=seed)
            if refused:
                write('step_result', convert.step_result_msg(
                    StepOutcome(0.0, np.zeros(cfg.plant_count), False, False, 0), step_id=0,
                    reset_id=reset_id, step=steps, stamp_ns=stamp, frame_id='chamber',
                    info='error: the target x = 9 m is outside the travel'), stamp)
                continue
            config(seed, reset_id, stamp)
            for step in range(steps + 1):
                step_id = step
                if step:
                    stamp = next(clock)
                    action = oracle.act(world.chamber)
                    write('light/command', convert.discrete_command_msg(
                        action, step_id, stamp, 'chamber'), stamp)
                    world.apply_discrete(action)
                    world.step()
                stamp = next(clock)
                light = convert.light_msg(world.chamber.light, step_id, stamp, 'chamber')
                c = world.chamber
                request = gantry_capture(stamp, step_id, c.steps, payload(
                    world, world.seed, reset_id), light, cfg, c.target, c.target_mask,
                    'chamber')
                reply = capture(request)
                m = reply.measurement
                if m.ok:
                    write('camera/image_raw', reply.observation, stamp)
                    write('plant/state', reply.plant, stamp)
                write('light/state', light, stamp)
                write('camera/photo', reply.photo, stamp)
                write('camera/measurement', m, stamp)
                outcome = StepOutcome(m.reward, np.asarray(m.plant_rewards), m.success, False,
                                      0) if m.ok else \
                    StepOutcome(0.0, np.zeros(cfg.plant_count), False, False, 0)
                write('step_result', convert.step_result_msg(
                    outcome, step_id=step_id, reset_id=reset_id, step=c.steps, stamp_ns=stamp,
                    frame_id='chamber',
                    info='' if m.ok else f'error: camera: {m.error_code}: {m.error}'), stamp)
    return path
