"""The photos of a rig's recording as people look at them: each with what the camera saw.

``growspace-camera export BAG DIR``: every recorded photo, measured again (settings as for
``resegment``), is written to ``DIR`` with camera/segmentation's drawing over it (the plant mask
in green, the markers outlined, the tips circled, the reason when not measured) and a caption
with the episode, the step and the reward, recorded and new.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from growspace_camera.pipeline import overlay, Pipeline
from growspace_camera.recorded import RecordedSteps
from growspace_camera.settings import CameraParams, load_layout
from growspace_sim.replay.bag import Bag, ReplayError

FORMATS = ('jpg', 'png')
SCALE_RANGE = (0.05, 1.0)
CAPTION_PX = 28  # height of the caption band under each picture


@dataclass
class ExportReport:
    """What an export wrote: ``files`` pictures, ``measured`` of them with a plant read."""

    files: int = 0
    measured: int = 0


def export_photos(path: str | os.PathLike, out: str | os.PathLike, params: CameraParams, *,
                  fmt: str = 'jpg', scale: float = 0.5, namespace: str | None = None,
                  warn: Callable[[str], Any] | None = None) -> ExportReport:
    """Write every recorded photo with the camera's drawing of it.

    Args:
        path: The recording (a lockstep gantry run with a camera).
        out: The folder to write to: created; if it exists it must be empty.
        params: The camera's settings (``PIPELINE_FIELDS`` matter).
        fmt: ``jpg`` or ``png``.
        scale: Size of the pictures relative to the photos, in ``SCALE_RANGE``.
        namespace: The chamber namespace; None = the only one.
        warn: Told of each unreadable part of the recording.

    Returns:
        The report. Files are named ``NNNNN_epEEE_stepSSSS.jpg`` (photo, episode, step).

    Raises:
        ReplayError: unreadable recording, no photos in it, a folder that holds files, or a
            format or scale not allowed.
        ParamError: the marker layout file cannot be read.
        OSError: a picture cannot be written.
    """
    if fmt not in FORMATS:
        raise ReplayError(f'--format {fmt!r} is not allowed; expected one of {FORMATS}.')
    if isinstance(scale, bool) or not SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]:
        raise ReplayError(f'--scale {scale!r} is not allowed; expected a size relative to the '
                          f'photo in [{SCALE_RANGE[0]}, {SCALE_RANGE[1]}].')
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ReplayError(f'{out} is not an empty folder: not writing into it.')
    pipeline = Pipeline(params.pipeline(load_layout(params.markers)))
    report = ExportReport()
    with Bag(path, on_damage=None if warn is None else lambda p: warn(f'skipped unreadable '
                                                                        f'{p}')) as bag:
        steps = RecordedSteps(bag, namespace)
        out.mkdir(parents=True, exist_ok=True)
        for step in steps:
            for photo in step.photos:
                m, bgr = photo.measure(pipeline)
                if bgr is None:
                    bgr = np.zeros((480, 640, 3), np.uint8)
                old = photo.result.decode() if photo.result is not None else None
                recorded = 'not recorded' if old is None else 'not measured' if old.info \
                    else f'{old.reward:.4f}'
                new = f'{m.reward:.4f}' if m.ok else 'NOT MEASURED'
                picture = _captioned(overlay(bgr, m, scale), f'episode {photo.episode} step '
                                     f'{photo.step}: reward {new} (recorded {recorded})')
                name = out / f'{report.files:05d}_ep{photo.episode:03d}_step{photo.step:04d}.{fmt}'
                if not cv2.imwrite(str(name), picture):
                    raise OSError(f'cannot write {name}')
                report.files += 1
                report.measured += m.ok
    if not report.files:
        raise ReplayError(f'{path} holds no readable photo on the camera/photo topic.')
    return report


def _captioned(picture: np.ndarray, text: str) -> np.ndarray:
    band = np.full((CAPTION_PX, picture.shape[1], 3), 255, np.uint8)
    cv2.putText(band, text, (6, CAPTION_PX - 9), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1,
                cv2.LINE_AA)
    return np.vstack((picture, band))
