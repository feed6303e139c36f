"""A rig's recording read back photo by photo, each with what the camera was told for it.

A lockstep gantry with a camera records, per reached move and all with the step's stamp:
``camera/image_raw``, ``plant/state``, ``light/state``, ``camera/photo`` (the JPEG),
``camera/measurement``, then ``step_result`` (docs/recording.md, the rig). ``RecordedSteps``
walks such a file in order and hands out the messages between two step_results (``Step``),
each photo in it with the step's context (``RecordedPhoto``): the reached light (the
``light/state`` of its stamp), the episode's configuration and target, and the step.

The target is the one the gantry sent the camera: its ``chamber/config`` payload records it
(``target``, ``growspace_sim.ros.interface.target_payload``), so it is read, never laid out
again. Recordings made before the gantry recorded its target have none: there, and only there,
the target is laid out again from each payload's challenge and seed as the simulator does, one
reset after the other (an unseeded reset continues the previous one's random stream), and the
payload's ``episode`` and ``digit`` check that the layout followed the gantry's. Where it cannot
(a reset the gantry laid out and refused, a lost reset), the photos of that episode say why,
and are not measured. Either way the step_result's ``reset_id`` must be the payload's.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
import json
from typing import Any

import cv2
import numpy as np

from growspace_camera.errors import BAD_INPUT, CameraError, NO_PHOTO
from growspace_camera.measure import Target
from growspace_camera.messages import light_from_msg
from growspace_camera.pipeline import Measurement, Pipeline
from growspace_sim.core.config import SimConfig
from growspace_sim.recording import METADATA_NAME
from growspace_sim.replay.bag import Bag, BagMessage, ReplayError
from growspace_sim.ros import convert
from growspace_sim.ros.interface import CAMERA_OUTPUTS, NAMES, target_from_payload
from growspace_sim.simulation import Simulation

IMAGE, PLANT, PHOTO, MEASUREMENT = (t.name for t in CAMERA_OUTPUTS)
LIGHT, RESULT, CONFIG = NAMES['light'], NAMES['result'], NAMES['config']
MEASURED = (IMAGE, PLANT, MEASUREMENT)  # the outputs a photo's measurement decides
CAMERA_ERROR = 'error: camera: '  # the gantry's step_result info for a photo not measured


@dataclass
class RecordedPhoto:
    """One recorded photo and the step it answered.

    Attributes:
        message: The ``camera/photo`` message.
        stamp: The step's stamp [ns] (every output of the step has it).
        episode: 0-based episode of the file (``chamber/config`` messages seen - 1).
        step: The episode's step (the step_result's; else one after the previous one).
        light: The ``light/state`` of the step (the reached light), if recorded.
        result: The ``step_result`` of the step, if recorded.
        measurement: The recorded ``camera/measurement`` of the step, if any.
        cfg: The episode's configuration (None when unknown).
        target: The episode's target (None when unknown).
        unknown: Why the step's context is unknown ('' when it is known).
    """

    message: BagMessage
    stamp: int
    episode: int
    step: int
    light: BagMessage | None = None
    result: BagMessage | None = None
    measurement: BagMessage | None = None
    cfg: SimConfig | None = None
    target: Target | None = None
    unknown: str = ''

    def measure(self, pipeline: Pipeline) -> tuple[Measurement, np.ndarray | None]:
        """Measure the photo as camera_node did for the step, with ``pipeline``'s settings.

        Returns:
            The measurement (``ok`` False, with the reason, when the photo or the step's
            context cannot be read) and the decoded photo (BGR; None if it is not one).
        """
        bgr = cv2.imdecode(np.asarray(self.message.decode().data, np.uint8),
                           cv2.IMREAD_COLOR)
        try:
            if bgr is None:
                raise CameraError(NO_PHOTO, 'the recorded camera/photo is not an image OpenCV '
                                  'can read')
            if self.unknown:
                raise CameraError(BAD_INPUT, self.unknown)
            if self.light is None:
                raise CameraError(BAD_INPUT, 'the light/state of this step (the reached light) '
                                  'is not in the recording')
            light = light_from_msg(self.light.decode())
        except CameraError as e:
            return Measurement(ok=False, error=e), bgr
        return pipeline.measure(bgr, self.cfg, light, self.target, self.step), bgr


@dataclass
class Step:
    """The messages from one step_result to the next (the last one included), in file order.

    Attributes:
        messages: The messages.
        photos: The photos among them, with their steps.
        lost: Stamps of steps the camera measured whose photo is not in the file (unreadable
            parts): their recorded camera outputs came from a photo that cannot be read again.
    """

    messages: list[BagMessage]
    photos: list[RecordedPhoto] = field(default_factory=list)
    lost: set[int] = field(default_factory=set)


class RecordedSteps:
    """The steps of a rig's lockstep recording, in file order (iterate once).

    Args:
        bag: The open recording.
        namespace: The chamber namespace; None = the only one.

    Raises:
        ReplayError: no chamber, no ``camera/photo`` topic, or a realtime recording.
    """

    def __init__(self, bag: Bag, namespace: str | None = None) -> None:
        names = bag.chamber_topics(namespace)
        prefix = names[RESULT][:-len(RESULT)]
        self.bag = bag
        self.topics = {rel: prefix + rel for rel in (PHOTO, *MEASURED, LIGHT, RESULT,
                                                     CONFIG)}
        self.names = {full: rel for rel, full in self.topics.items()}
        if self.topics[PHOTO] not in bag.topics:
            raise ReplayError(
                f"{bag.path} has no {self.topics[PHOTO]} topic: not a recording of the rig's "
                f"camera (gantry_node in lockstep with camera_node records each step's photo "
                f'there), so there is no photo to segment; recorded topics: '
                f'{", ".join(sorted(bag.topics))}.')
        meta = bag.metadata.get(METADATA_NAME, {})
        if meta.get('mode') == 'realtime':
            raise ReplayError(f'{bag.path} is a realtime recording: photos are re-measured step '
                              f'by step, from lockstep recordings (gantry_node mode:=lockstep).')
        self.episodes = _Episodes(meta.get('digit_source') or 'auto')

    def __iter__(self) -> Iterator[Step]:
        group: list[BagMessage] = []
        contexts: dict[int, tuple] = {}  # photo index in the group -> episode context
        last_step = -1
        for msg in self.bag.messages():
            rel = self.names.get(msg.topic)
            if rel == CONFIG:
                self.episodes.on_config(msg.decode().data)
            elif rel == PHOTO:
                contexts[len(group)] = self.episodes.context()
            group.append(msg)
            if rel == RESULT:
                step, last_step = self._step(group, contexts, last_step)
                yield step
                group, contexts = [], {}
        if group:
            yield self._step(group, contexts, last_step)[0]

    def _step(self, group: list[BagMessage], contexts: dict[int, tuple],
              last_step: int) -> tuple[Step, int]:
        stamps: dict[int, dict[str, BagMessage]] = {}  # stamp -> topic -> last message
        results = []
        for msg in group:
            rel = self.names.get(msg.topic)
            if rel in (PHOTO, *MEASURED, LIGHT, RESULT):
                decoded = msg.decode()
                stamp = convert.to_ns(decoded.header.stamp)
                stamps.setdefault(stamp, {})[rel] = msg
                if rel == RESULT:
                    results.append((stamp, decoded))
        step = Step(group)
        for i, (episode, cfg, target, unknown, reset_id) in contexts.items():
            msg = group[i]
            stamp = convert.to_ns(msg.decode().header.stamp)
            mine = stamps[stamp]
            result = next((r for s, r in results if s == stamp), None)
            if result is not None:
                last_step = int(result.step)
                if not unknown and reset_id is not None and int(result.reset_id) != reset_id:
                    unknown = (f'the step answers reset_id {int(result.reset_id)}, whose '
                               f'chamber/config is not in the recording (the last one read is '
                               f'reset_id {reset_id}): its target is unknown')
            else:
                last_step += 1
            step.photos.append(RecordedPhoto(msg, stamp, episode, last_step, mine.get(LIGHT),
                                             mine.get(RESULT), mine.get(MEASUREMENT), cfg,
                                             target, unknown))
        photographed = {p.stamp for p in step.photos}
        for stamp, topics in stamps.items():
            if stamp in photographed:
                continue
            result = next((r for s, r in results if s == stamp), None)
            measured = any(rel in topics for rel in MEASURED) or (
                result is not None and not result.info)
            if measured and self.bag.damage:
                step.lost.add(stamp)
        return step, last_step


class _Episodes:
    """The episodes' configurations and targets: recorded, or (older recordings) laid out again
    reset after reset."""

    def __init__(self, digit_source: str) -> None:
        self.digit_source = digit_source
        self.sim: Simulation | None = None
        self.index = -1
        self.cfg: SimConfig | None = None
        self.target: Target | None = None
        self.reset_id: int | None = None
        self.unknown = 'no chamber/config was recorded before this photo: its challenge and ' \
            'target are unknown'
        self.followed = False  # the random stream is where the gantry's was

    def context(self) -> tuple:
        return self.index, self.cfg, self.target, self.unknown, self.reset_id

    def on_config(self, text: str) -> None:
        self.index += 1
        self.cfg = self.target = self.reset_id = None
        try:
            payload = json.loads(text)
            cfg = SimConfig.from_dict(payload['config'])
            self.unknown = self._recorded(payload, cfg) if 'target' in payload else \
                self._lay_out(payload, cfg)
        except (ValueError, KeyError, TypeError, FileNotFoundError, CameraError) as e:
            self.unknown = f'its chamber/config cannot be read: {e}'
        if not self.unknown:
            reset_id = payload.get('reset_id')
            self.reset_id = reset_id if isinstance(reset_id, int) else None
        if self.unknown:
            self.followed = False
            self.unknown = f'episode {self.index}: {self.unknown}'

    def _recorded(self, payload: dict, cfg: SimConfig) -> str:
        """The target the gantry recorded (and sent the camera)."""
        point, mask = target_from_payload(payload['target'])
        target = Target(point=point, mask=mask)
        target.check(cfg)
        self.cfg, self.target = cfg, target
        self.followed = False  # no stream followed: a later payload without a target can't be
        return ''

    def _lay_out(self, payload: dict, cfg: SimConfig) -> str:
        """A recording made before the gantry recorded its target: lay it out again."""
        seed = payload.get('seed')
        if not isinstance(seed, int) or isinstance(seed, bool):
            seed = None
        if seed is None and not self.followed:
            return ('its reset continues the random stream of an episode that could not be '
                    'followed (no seed recorded), so its target is unknown (this recording '
                    "predates the target in the gantry's chamber/config)")
        sim = self.sim
        sim = Simulation(cfg, self.digit_source) if sim is None else \
            sim.with_config(cfg) if cfg != sim.cfg else sim
        sim.reset(seed=seed)
        self.sim, self.followed = sim, True
        for key, mine in (('episode', sim.episode), ('digit', sim.digit)):
            if key in payload and payload[key] != mine:
                return (f'its target was not laid out as the gantry did ({key} {payload[key]!r} '
                        f'recorded, {mine!r} here: a reset the recording does not hold, or one '
                        f'the gantry laid out and refused; this recording predates the target '
                        f"in the gantry's chamber/config)")
        chamber = sim.chamber
        self.cfg = cfg
        self.target = Target(point=chamber.target) if cfg.task.digits is None else \
            Target(mask=np.asarray(chamber.target_mask, bool))
        return ''


def step_result_of(recorded: Any, m: Measurement, cfg: SimConfig | None) -> Any:
    """A step_result with the reward, plant rewards, success and info of a new measurement
    (the rest as recorded), as the gantry answers a step from its photo."""
    if m.ok:
        recorded.reward, recorded.success, recorded.info = float(m.reward), bool(m.success), ''
        recorded.plant_rewards = np.asarray(m.plant_rewards, np.float64)
    else:
        plants = cfg.plant_count if cfg is not None else len(recorded.plant_rewards)
        recorded.reward, recorded.success = 0.0, False
        recorded.plant_rewards = np.zeros(plants, np.float64)
        recorded.info = f'{CAMERA_ERROR}{m.error}'
    return recorded
