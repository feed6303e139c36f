"""Re-segment a rig's recording with other settings, into a new recording.

``growspace-camera resegment IN.mcap OUT.mcap --set min_greenness=0.1``: every recorded photo
is measured again by the camera pipeline, in recorded order (so a plane fit is held across
photos as camera_node held it), with the step's recorded light, the episode's target and the
new settings. The new file holds every message of the old one, byte for byte, in the same
order, channels and metadata records, except each photographed step's camera outputs, which
are the new measurement's, as the gantry would have published them: ``camera/image_raw`` and
``plant/state`` (only from a measured photo), ``camera/measurement``, and the step_result's
reward, plant rewards, success and info. A metadata record ``growspace_resegment`` says from
what file and with which settings. The input is only read.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
import hashlib
import json
import os
from pathlib import Path
from typing import Any

from growspace_camera import messages as wire
from growspace_camera.errors import CameraError, NO_PHOTO
from growspace_camera.pipeline import Measurement, Pipeline
from growspace_camera.recorded import (
    IMAGE, LIGHT, MEASUREMENT, PHOTO, PLANT, RecordedPhoto, RecordedSteps,
    MEASURED, RESULT, Step, step_result_of)
from growspace_camera.settings import (
    CameraParams, load_layout, pipeline_values, with_overrides)
from growspace_sim import __version__
from growspace_sim.recording import McapRecorder
from growspace_sim.recording.scan import damage_metadata, RECOVERY_METADATA
from growspace_sim.replay.bag import Bag, BagMessage, ReplayError
from growspace_sim.ros import convert, types
from growspace_sim.ros.interface import CAMERA_OUTPUTS, OBSERVATION_QOS

RESEGMENT_METADATA = 'growspace_resegment'
IMAGE_FRAME = CameraParams().image_frame_id  # until the file shows the observations' frame
TYPES = {**{t.name: t.typename for t in CAMERA_OUTPUTS}, RESULT: types.STEP_RESULT}
LOST = 'the photo of this step is in an unreadable part of the recording: not measured again'


@dataclass
class ResegmentReport:
    """What a re-segmentation did.

    Attributes:
        photos: Photos measured again.
        measured: ... of which the new settings read (``ok``).
        changed: Steps whose reward, success or measured/not measured changed.
        was_measured: Photos the recording had measured.
        lost: Measured steps whose photo is in an unreadable part of the input (now unmeasured).
        messages: Messages written.
        warnings: Lines for the user (unreadable parts of the input).
    """

    photos: int = 0
    measured: int = 0
    changed: int = 0
    was_measured: int = 0
    lost: int = 0
    messages: int = 0
    warnings: list[str] = field(default_factory=list)


def resegment(path: str | os.PathLike, out: str | os.PathLike, params: CameraParams, *,
              base: str = 'camera_node defaults', namespace: str | None = None,
              warn: Callable[[str], Any] | None = None) -> ResegmentReport:
    """Write a copy of a rig's recording with every photo measured again.

    Args:
        path: The recording (a lockstep gantry run with a camera).
        out: The new ``.mcap`` file; never an existing file.
        params: The camera's settings (``PIPELINE_FIELDS`` matter).
        base: What ``params`` started from, for the metadata (e.g. ``camera_node defaults``).
        namespace: The chamber namespace; None = the only one.
        warn: Told of each unreadable part of the input as reading meets it.

    Returns:
        The report.

    Raises:
        ReplayError: unreadable or truncated input (the message says how to recover it), no
            chamber or no ``camera/photo`` in it, or an output that exists or is the input.
        RecordingError: the output cannot be written.
        ParamError: the marker layout file cannot be read.
    """
    path, out = Path(path), Path(out)
    if out.suffix != '.mcap':
        raise ReplayError(f'Cannot write the re-segmented recording to {out}: use a .mcap file '
                          f'name.')
    if out.exists():
        raise ReplayError(f'{out} exists already, not overwriting'
                          f'{" (it is the input)" if _same(path, out) else ""}.')
    layout = load_layout(params.markers)
    pipeline = Pipeline(params.pipeline(layout))
    report = ResegmentReport()

    def damaged(part: Any) -> None:
        report.warnings.append(f'skipped unreadable {part}')
        if warn is not None:
            warn(report.warnings[-1])

    with Bag(path, on_damage=damaged) as bag:
        inherited = list(bag.damage)
        steps = RecordedSteps(bag, namespace)
        recorder = McapRecorder(out)
        try:
            writer = _Writer(recorder, bag, steps.topics, pipeline, params, report)
            for step in steps:
                writer.step(step)
            new_damage = [part for part in bag.damage if part not in inherited]
            if new_damage:  # the holes of this copy, as recover() records them
                recorder.add_metadata(RECOVERY_METADATA, damage_metadata(path.name, bag.damage))
            recorder.add_metadata(RESEGMENT_METADATA, {
                'source': str(path), 'source_sha256': _sha256(path),
                'version': __version__, 'base': base,
                'settings': json.dumps(pipeline_values(params), sort_keys=True),
                'markers_layout': json.dumps(_layout_dict(layout), sort_keys=True),
                'photos': str(report.photos), 'measured': str(report.measured),
                'was_measured': str(report.was_measured), 'changed': str(report.changed),
                'lost': str(report.lost)})
            recorder.close()
        except BaseException:
            recorder.close()
            out.unlink(missing_ok=True)  # ours: created by the recorder ('x' mode) above
            raise
    return report


class _Writer:
    """Writes each step: copied messages, and new camera outputs where its photos are."""

    def __init__(self, recorder: McapRecorder, bag: Bag, topics: dict[str, str],
                 pipeline: Pipeline, params: CameraParams, report: ResegmentReport) -> None:
        self.recorder, self.topics, self.names = recorder, topics, {f: r for r, f in
                                                                      topics.items()}
        self.pipeline, self.params, self.report = pipeline, params, report
        self.channels = {t: recorder.add_channel(t, i.typename, i.qos)
                         for t, i in bag.topics.items()}
        for name, data in bag.metadata.items():
            if name != RESEGMENT_METADATA:  # this run writes its own (it names its source)
                recorder.add_metadata(name, data)
        self.image_frame = IMAGE_FRAME  # the recorded observations' frame, once one is seen

    def step(self, step: Step) -> None:
        new = {photo.stamp: self._measure(photo) for photo in step.photos}
        self.report.lost += len(step.lost)
        for msg in step.messages:
            rel = self.names.get(msg.topic)
            if rel not in (*MEASURED, LIGHT, PHOTO, RESULT):
                self._copy(msg)
                continue
            decoded = msg.decode()
            stamp = convert.to_ns(decoded.header.stamp)
            if rel == IMAGE:
                self.image_frame = decoded.header.frame_id
            if stamp in step.lost:  # measured from a photo that cannot be read again
                if rel == RESULT:
                    self._write(msg, RESULT, step_result_of(decoded, Measurement(
                        ok=False, error=CameraError(NO_PHOTO, LOST)), None))
                elif rel not in MEASURED:
                    self._copy(msg)
                continue
            if stamp not in new:
                self._copy(msg)
                continue
            photo, m = new[stamp]
            if rel in MEASURED:
                continue  # replaced: the new ones are written below, in the gantry's order
            if msg is photo.light or (rel == PHOTO and photo.light is None):
                self._outputs(msg, photo, m, (IMAGE, PLANT))
            if rel == RESULT:
                self._write(msg, RESULT, step_result_of(decoded, m, photo.cfg))
                continue
            self._copy(msg)
            if msg is photo.message:
                self._outputs(photo.measurement or msg, photo, m, (MEASUREMENT,))

    def _measure(self, photo: RecordedPhoto) -> tuple[RecordedPhoto, Measurement]:
        m, _ = photo.measure(self.pipeline)
        report = self.report
        report.photos += 1
        report.measured += m.ok
        old = photo.result.decode() if photo.result is not None else None
        was = old is not None and not old.info
        report.was_measured += was
        if old is not None and (was != m.ok or (m.ok and (old.reward != m.reward
                                                          or old.success != m.success))):
            report.changed += 1
        return photo, m

    def _outputs(self, at: BagMessage, photo: RecordedPhoto, m: Measurement,
                 which: tuple[str, ...]) -> None:
        """New camera outputs of a step, stamped and framed as its recorded messages, with the
        log and publish times of ``at``."""
        recorded = photo.measurement.decode() if photo.measurement is not None else None
        frame = recorded.header.frame_id if recorded is not None else \
            photo.light.decode().header.frame_id if photo.light is not None else \
            self.params.frame_id
        step_id = int(photo.result.decode().step_id) if photo.result is not None else \
            int(recorded.step_id) if recorded is not None else 0
        if IMAGE in which and m.ok:
            self._write(at, IMAGE, wire.observation_msg(m, photo.stamp, self.image_frame))
        if PLANT in which and m.ok:
            self._write(at, PLANT, wire.plant_msg(m, photo.stamp, step_id, frame))
        if MEASUREMENT in which:
            self._write(at, MEASUREMENT, wire.measurement_msg(m, photo.stamp, step_id, frame,
                                                              self.params.pixel_size_m))

    def _copy(self, msg: BagMessage) -> None:
        self.recorder.write(self.channels[msg.topic], msg.data, msg.log_time, msg.publish_time)
        self.report.messages += 1

    def _write(self, at: BagMessage, rel: str, msg: Any) -> None:
        topic, typename = self.topics[rel], TYPES[rel]
        channel = self.channels.get(topic)
        if channel is None:  # a topic the input never recorded (every photo failed there)
            channel = self.channels[topic] = self.recorder.add_channel(topic, typename,
                                                                       OBSERVATION_QOS)
        self.recorder.write(channel, types.serialize(msg, typename), at.log_time,
                            at.publish_time)
        self.report.messages += 1


def _same(a: Path, b: Path) -> bool:
    try:
        return a.samefile(b)
    except OSError:
        return False


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, 'rb') as f:
        for block in iter(lambda: f.read(1 << 20), b''):
            digest.update(block)
    return digest.hexdigest()


def _layout_dict(layout: Any) -> dict[str, Any]:
    return {'dictionary': layout.dictionary, 'side_m': layout.side, 'ids': list(layout.ids),
            'centres_m': [list(c) for c in layout.centres]}


def recorded_settings(path: str | os.PathLike) -> tuple[CameraParams, str]:
    """The settings a recording's measurements were made with, as far as it says.

    Returns:
        The settings and where they come from: a re-segmented recording's own record, else
        camera_node's defaults (a rig's recording does not hold camera_node's parameters).

    Raises:
        ReplayError: unreadable recording.
        ParamError: a ``growspace_resegment`` record whose settings are not valid here.
    """
    with Bag(path) as bag:
        record = bag.metadata.get(RESEGMENT_METADATA)
    if record is None:
        return CameraParams(), 'camera_node defaults'
    try:
        values = json.loads(record['settings'])
    except (KeyError, ValueError) as e:
        raise ReplayError(f'{path}: its {RESEGMENT_METADATA} record has no readable settings: '
                          f'{e!r}') from None
    return with_overrides(CameraParams(), values, f'{path} ({RESEGMENT_METADATA})'), \
        f'the settings recorded in {Path(path).name} ({RESEGMENT_METADATA})'
