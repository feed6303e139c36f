"""camera_node's own settings (beside every ``SimConfig`` field, which says the challenge), and
the marker layout file.

The markers' layout is a YAML file (``config/markers.yaml``) rather than parameters: it is the
rig's physical description, like the gantry's calibration, and ``growspace-camera markers``
prints the sheet from the same file the node reads.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
import os
import re
from typing import Any

import yaml

from growspace_camera.markers import MarkerLayout
from growspace_camera.pipeline import PipelineParams
from growspace_camera.segment import SegmentParams
from growspace_camera.skeleton import TreeParams
from growspace_sim.core.config import Bounds
from growspace_sim.node.params import check_bounds, MODES, ParamError
from growspace_sim.ros.convert import MAX_SEED

_FRACTION = Bounds(0.0, 1.0, low_open=True)
# The ranges of CameraParams' number fields: what validation checks and ROS parameters show.
CAMERA_BOUNDS = {
    'width': Bounds(16, 8192, integer=True), 'height': Bounds(16, 8192, integer=True),
    'fps': Bounds(0.0, 240.0, low_open=True), 'exposure': Bounds(1.0, 1e6, sentinel=-1),
    'white_balance_k': Bounds(1000, 15000, integer=True, sentinel=0),
    'flush_frames': Bounds(0, 30, integer=True), 'rate_hz': Bounds(0.0, 100.0, low_open=True),
    'retry_max_s': Bounds(0.5, 3600.0), 'jpeg_quality': Bounds(10, 100, integer=True),
    'twin_seed': Bounds(0, MAX_SEED, integer=True),
    'seed': Bounds(0, MAX_SEED, integer=True, sentinel=-1),
    'pixel_size_m': Bounds(0.0005, 0.02), 'min_greenness': Bounds(0.0, 1.0),
    'min_contrast': Bounds(0.0, 1.0), 'min_area_m2': Bounds(0.0, 0.01),
    'dark_level': Bounds(0.0, 1.0), 'max_saturated': _FRACTION,
    'base_band_m': Bounds(0.002, 0.5), 'spur_m': Bounds(0.0, 0.5),
    'spur_radii': Bounds(0.0, 20.0), 'corner_deg': Bounds(1.0, 90.0),
    'min_stem_m': Bounds(0.0, 1.0),
    'max_fit_error_m': Bounds(0.0001, 0.1), 'segmentation_scale': Bounds(0.05, 1.0),
}
SOURCE_RULE = ("'twin', a V4L2 device (/dev/videoN or its index), a video file, a folder of "
               "photos or a glob such as 'shots/*.jpg'")


@dataclass(frozen=True)
class CameraParams:
    """Settings of camera_node, validated on construction (ROS parameters of the same names)."""

    mode: str = 'lockstep'  # lockstep: photos on camera/capture requests; realtime: on a timer
    source: str = 'twin'  # 'twin', /dev/videoN or its index, a video file, a folder or a glob
    width: int = 1920  # px, asked of a device (the log says what it accepted)
    height: int = 1080  # px
    fps: float = 30.0  # frames per second asked of a device
    exposure: float = -1.0  # device exposure (V4L2 exposure_time_absolute, 100 us); -1 = auto
    white_balance_k: int = 0  # device white balance [K]; 0 = auto (both warned: lock them)
    flush_frames: int = 2  # frames dropped before a photo (a device buffers stale ones)
    loop: bool = True  # a video file or a folder of photos starts again at its end
    rate_hz: float = 1.0  # Hz; photos per second in realtime mode
    retry_max_s: float = 10.0  # s; longest wait between two tries to reopen a lost source
    jpeg_quality: int = 90  # JPEG quality of camera/photo when the source gives no JPEG
    twin_seed: int = 0  # seed of the twin source's photos (poses, light, noise)
    seed: int = -1  # seed of the first episode's target when no chamber/config came; -1 = none
    markers: str = ''  # marker layout YAML; empty = the installed config/markers.yaml
    pixel_size_m: float = 0.002  # side of a rectified pixel on the plant plane [m]
    min_greenness: float = 0.06  # lowest excess-green threshold (an empty pot stays empty)
    min_contrast: float = 0.08  # plant minus backdrop greenness below this: no plant
    min_area_m2: float = 0.0001  # smaller specks of green are not plant [m^2]
    dark_level: float = 0.08  # a photo darker than this mean grey level is refused [0-1]
    max_saturated: float = 0.2  # a photo with more clipped pixels is refused [0-1]
    base_band_m: float = 0.03  # skeleton this close to the floor is a stem base [m]
    spur_m: float = 0.015  # end branches shorter than this are thinning spurs [m]
    spur_radii: float = 2.0  # ... or shorter than this many stem radii
    corner_deg: float = 15.0  # a skeleton turning this much has a node there [deg]
    min_stem_m: float = 0.05  # a stem base carrying less plant than this is a speck [m]
    max_fit_error_m: float = 0.005  # largest RMS marker-corner error of a plane fit [m]
    segmentation_scale: float = 0.5  # size of camera/segmentation relative to the photo
    frame_id: str = 'chamber'  # frame of plant state and measurements
    image_frame_id: str = 'chamber_camera'  # frame of the observation image
    photo_frame_id: str = 'camera_optical'  # frame of the photos (the camera's optical frame)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ParamError(f'mode must be one of {MODES}, got {self.mode!r}.')
        if not isinstance(self.source, str) or not self.source.strip():
            raise ParamError(f'source must be {SOURCE_RULE}, got {self.source!r}.')
        check_bounds(self, CAMERA_BOUNDS)
        for name in ('loop',):
            if not isinstance(getattr(self, name), bool):
                raise ParamError(f'{name} must be a bool, got {getattr(self, name)!r}.')
        for name in ('frame_id', 'image_frame_id', 'photo_frame_id'):
            value = getattr(self, name)
            if not isinstance(value, str) or not re.fullmatch(r'[A-Za-z0-9_/]+', value):
                raise ParamError(f'{name} must be a frame name of letters, digits, _ and /, '
                                 f'got {value!r}.')
        if not isinstance(self.markers, str):
            raise ParamError(f'markers must be a path (string), got {self.markers!r}.')

    def pipeline(self, layout: MarkerLayout) -> PipelineParams:
        """The pipeline's parameters."""
        segment = SegmentParams(**{f.name: getattr(self, _SEGMENT_NAMES.get(f.name, f.name))
                                   for f in fields(SegmentParams)})
        tree = TreeParams(**{f.name: getattr(self, f.name) for f in fields(TreeParams)})
        return PipelineParams(layout, segment, tree, self.max_fit_error_m)


_SEGMENT_NAMES = {'pixel_m': 'pixel_size_m'}


def default_markers() -> str:
    """The installed ``config/markers.yaml`` (or the source tree's, when not installed)."""
    try:
        from ament_index_python.packages import get_package_share_directory

        return os.path.join(get_package_share_directory('growspace_camera'), 'config',
                            'markers.yaml')
    except Exception:  # noqa: BLE001 - not installed: the source tree
        return os.path.join(os.path.dirname(__file__), '..', 'config', 'markers.yaml')


def load_layout(path: str = '') -> MarkerLayout:
    """Read a marker layout YAML (keys: dictionary, side_m, ids, centres_m).

    Raises:
        ParamError: naming the file and the key for a missing file, unknown keys or a bad
            value.
    """
    path = path or default_markers()
    try:
        with open(path, encoding='utf-8') as f:
            data = yaml.safe_load(f)
    except OSError as e:
        raise ParamError(f'markers = {path!r} cannot be read: {e.strerror or e}') from None
    except yaml.YAMLError as e:
        raise ParamError(f'markers = {path!r} is not YAML: {e}') from None
    return layout_from_dict(data, path)


def layout_from_dict(data: Any, where: str = 'markers') -> MarkerLayout:
    """A ``MarkerLayout`` from the YAML's mapping.

    Raises:
        ParamError: unknown or missing keys, or values ``MarkerLayout`` refuses.
    """
    keys = {'dictionary', 'side_m', 'ids', 'centres_m'}
    if not isinstance(data, dict) or set(data) != keys:
        got = sorted(data) if isinstance(data, dict) else type(data).__name__
        raise ParamError(f'{where}: needs exactly the keys {sorted(keys)}, got {got}.')
    try:
        centres = tuple((float(c[0]), float(c[1])) for c in data['centres_m'])
        if not all(len(c) == 2 for c in data['centres_m']):
            raise ValueError
        ids = tuple(data['ids'])
        side = data['side_m']
        if isinstance(side, bool) or not isinstance(side, (int, float)):
            raise ValueError
    except (TypeError, ValueError, IndexError):
        raise ParamError(f'{where}: centres_m must be a list of [x, z] pairs in metres, ids a '
                         f'list of ints and side_m a number; got centres_m = '
                         f'{data["centres_m"]!r}, ids = {data["ids"]!r}, side_m = '
                         f'{data["side_m"]!r}.') from None
    try:
        return MarkerLayout(dictionary=data['dictionary'], ids=ids, centres=centres,
                            side=float(side))
    except ValueError as e:
        raise ParamError(f'{where}: {e}') from None
