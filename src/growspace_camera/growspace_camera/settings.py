"""camera_node's own settings (beside every ``SimConfig`` field, which says the challenge), and
the marker layout file.

The markers' layout is a YAML file (``config/markers.yaml``) rather than parameters: it is the
rig's physical description, like the gantry's calibration, and ``growspace-camera markers``
prints the sheet from the same file the node reads.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
import yaml

from growspace_camera.lens import Lens
from growspace_camera.markers import MarkerLayout
from growspace_camera.pipeline import PipelineParams
from growspace_camera.segment import SegmentParams
from growspace_camera.skeleton import TreeParams
from growspace_sim.core.schema import Bounds, param
from growspace_sim.node.params import (
    check, check_type, frame_param, mode_param, ParamError, seed_param, specs_of)
from growspace_sim.ros.convert import MAX_SEED
from growspace_sim.ros.share import share_file

_FRACTION = Bounds(0.0, 1.0, low_open=True)
SOURCE_RULE = ("'twin', a V4L2 device (/dev/videoN or its index), a video file, a folder of "
               "photos or a glob such as 'shots/*.jpg'")


@dataclass(frozen=True)
class CameraParams:
    """Settings of camera_node, validated on construction (ROS parameters of the same names),
    each declared once (``growspace_sim.core.schema.param``)."""

    mode: str = mode_param('lockstep: photos on camera/capture requests; realtime: on a timer')
    source: str = param('twin', 'where photos come from', pattern=r'\S.*',
                        pattern_doc=SOURCE_RULE)
    width: int = param(1920, 'photo width asked of a device (the log says what it accepted)',
                       unit='px', bounds=Bounds(16, 8192, integer=True))
    height: int = param(1080, 'photo height asked of a device', unit='px',
                        bounds=Bounds(16, 8192, integer=True))
    fps: float = param(30.0, 'frames per second asked of a device', unit='Hz',
                       bounds=Bounds(0.0, 240.0, low_open=True))
    exposure: float = param(-1.0, 'device exposure (V4L2 exposure_time_absolute)',
                            unit='100 us', bounds=Bounds(1.0, 1e6, sentinel=-1),
                            rule='-1 = auto (warned: lock it)')
    white_balance_k: int = param(0, 'device white balance', unit='K',
                                 bounds=Bounds(1000, 15000, integer=True, sentinel=0),
                                 rule='0 = auto (warned: lock it)')
    flush_frames: int = param(2, 'frames dropped before a photo (a device buffers stale ones)',
                              bounds=Bounds(0, 30, integer=True))
    loop: bool = param(True, 'a video file or a folder of photos starts again at its end')
    rate_hz: float = param(1.0, 'photos per second in realtime mode', unit='Hz',
                           bounds=Bounds(0.0, 100.0, low_open=True))
    retry_max_s: float = param(10.0, 'longest wait between two tries to reopen a lost source',
                               unit='s', bounds=Bounds(0.5, 3600.0))
    jpeg_quality: int = param(90, 'JPEG quality of camera/photo when the source gives no JPEG',
                              bounds=Bounds(10, 100, integer=True))
    twin_seed: int = param(0, "seed of the twin source's photos (poses, light, noise)",
                           bounds=Bounds(0, MAX_SEED, integer=True))
    seed: int = seed_param("seed of the first episode's target when no chamber/config came")
    markers: str = param('', 'marker layout YAML; empty = the installed config/markers.yaml')
    lens: str = param('', "the camera's calibration YAML (ROS camera_calibration's: "
                      'camera_matrix, distortion_coefficients); empty = no lens distortion')
    pixel_size_m: float = param(0.0025, 'side of a rectified pixel on the plant plane', unit='m',
                                bounds=Bounds(0.0005, 0.02))
    min_greenness: float = param(0.06, 'lowest excess-green threshold (an empty pot stays '
                                 'empty)', unit='1', bounds=Bounds(0.0, 1.0))
    min_contrast: float = param(0.08, 'plant minus backdrop greenness below this: no plant',
                                unit='1', bounds=Bounds(0.0, 1.0))
    min_area_m2: float = param(0.0001, 'smaller specks of green are not plant', unit='m^2',
                               bounds=Bounds(0.0, 0.01))
    dark_level: float = param(0.08, 'a photo darker than this mean grey level is refused',
                              unit='0-1', bounds=Bounds(0.0, 1.0))
    max_saturated: float = param(0.2, 'a photo with more clipped pixels is refused',
                                 unit='fraction', bounds=_FRACTION)
    base_band_m: float = param(0.03, 'skeleton this close to the floor is a stem base',
                               unit='m', bounds=Bounds(0.002, 0.5))
    spur_m: float = param(0.015, 'end branches shorter than this are thinning spurs', unit='m',
                          bounds=Bounds(0.0, 0.5))
    spur_radii: float = param(2.0, '... or shorter than this many stem radii', unit='radii',
                              bounds=Bounds(0.0, 20.0))
    spur_taper: float = param(0.5, 'a short end branch thinner at its end than this fraction '
                              'of the stem it leaves is a shoot, not a spur', unit='1',
                              bounds=Bounds(0.0, 1.0), rule='0 = every short one is a spur')
    corner_deg: float = param(15.0, 'a skeleton turning this much has a node there',
                              unit='deg', bounds=Bounds(1.0, 90.0))
    min_stem_m: float = param(0.05, 'a stem base carrying less plant than this is a speck',
                              unit='m', bounds=Bounds(0.0, 1.0))
    max_base_tilt_deg: float = param(35.0, 'plant reaching the floor is a stem base only if it '
                                     'rises within this angle of vertical (else a leaf)',
                                     unit='deg', bounds=Bounds(0.0, 90.0))
    leaf_widening: float = param(1.5, 'an end branch widening to this many times its narrowest '
                                 'radius ends in a leaf, cut off its shoot', unit='1',
                                 bounds=Bounds(0.0, 10.0), rule='0 = no leaves are cut')
    petiole_m: float = param(0.025, 'a shoot left shorter than this by a leaf cut is a '
                             'petiole: all leaf', unit='m', bounds=Bounds(0.0, 0.5))
    leaf_end_m: float = param(0.019, "an end branch this wide near its end is a leaf blade (a "
                              "shoot's end is thinner)", unit='m', bounds=Bounds(0.0, 0.5),
                              rule='0 = off')
    max_fit_error_m: float = param(0.005, 'largest RMS marker-corner error of a plane fit',
                                   unit='m', bounds=Bounds(0.0001, 0.1))
    max_unexplained: float = param(0.5, 'largest share of the plant mask in pieces that hold '
                                   'no stem base; more: the photo is refused (unexplained)',
                                   unit='fraction', bounds=Bounds(0.0, 1.0))
    max_loops: int = param(20, 'most loops (holes) in the plant mask, where branches and '
                           'leaves cross; more: the photo is refused (unexplained)',
                           bounds=Bounds(0, 100000, integer=True))
    max_share_gap: float = param(0.25, "largest gap between touching plants' shares of the "
                                 "skeleton and their stems' (radius cubed); more: the photo "
                                 'is refused (plants)', unit='fraction', bounds=Bounds(0.0, 1.0))
    max_float_m: float = param(0.05, 'farthest over the measured plants a piece of plant that '
                               'reaches no stem base may lie (a flower cluster over a stem the '
                               'mask missed); farther: the photo is refused (unexplained)',
                               unit='m', bounds=Bounds(0.0, 1.0), rule='0 = off')
    segmentation_scale: float = param(0.5, 'size of camera/segmentation relative to the photo',
                                      unit='1', bounds=Bounds(0.05, 1.0))
    frame_id: str = frame_param('chamber', 'frame of plant state and measurements')
    image_frame_id: str = frame_param('chamber_camera', 'frame of the observation image')
    photo_frame_id: str = frame_param('camera_optical',
                                      "frame of the photos (the camera's optical frame)")

    def __post_init__(self) -> None:
        check(self)

    def pipeline(self, layout: MarkerLayout) -> PipelineParams:
        """The pipeline's parameters."""
        segment = SegmentParams(**{f.name: getattr(self, _SEGMENT_NAMES.get(f.name, f.name))
                                   for f in fields(SegmentParams)})
        tree = TreeParams(**{f.name: getattr(self, f.name) for f in fields(TreeParams)})
        return PipelineParams(layout, segment, tree, self.max_fit_error_m,
                              self.max_unexplained, load_lens(self.lens) if self.lens else None,
                              self.max_loops, self.max_share_gap, self.max_float_m)


_SEGMENT_NAMES = {'pixel_m': 'pixel_size_m'}
# The settings that change what a photo gives (the rest say where photos come from and how
# they are published): what ``growspace-camera resegment`` and ``export`` take.
PIPELINE_FIELDS = ('markers', 'lens',
                   *(_SEGMENT_NAMES.get(f.name, f.name) for f in fields(SegmentParams)),
                   *(f.name for f in fields(TreeParams)), 'max_fit_error_m',
                   'max_unexplained', 'max_loops', 'max_share_gap', 'max_float_m')


def pipeline_values(params: CameraParams) -> dict[str, Any]:
    """The ``PIPELINE_FIELDS`` of some settings, by name."""
    return {name: getattr(params, name) for name in PIPELINE_FIELDS}


def with_overrides(params: CameraParams, values: dict[str, Any], where: str) -> CameraParams:
    """Settings with some pipeline settings changed, each checked as camera_node checks it.

    Args:
        params: The settings to start from.
        values: Name -> value (YAML types: numbers, strings).
        where: Where the values come from, for the message (``--set``, a file name).

    Raises:
        ParamError: naming the setting, its value and what is allowed; for a name that is not
            a pipeline setting, the names that are.
    """
    specs = {s.name: s for s in specs_of(CameraParams)}
    changed = {}
    for name, value in values.items():
        if name not in PIPELINE_FIELDS:
            raise ParamError(f'{where}: {name!r} is not a setting of the camera pipeline; '
                             f'allowed: {", ".join(PIPELINE_FIELDS)}.')
        try:
            changed[name] = check_type(specs[name], value)
        except ParamError as e:
            raise ParamError(f'{where}: {e}') from None
    try:
        return replace(params, **changed)
    except ValueError as e:
        raise ParamError(f'{where}: {e}') from None


def read_overrides(path: str) -> dict[str, Any]:
    """Pipeline settings from a YAML file: a plain mapping of name: value, or camera_node's
    ROS params file (``NODE: {ros__parameters: {...}}``), whose other settings are left out.

    Raises:
        ParamError: naming the file for an unreadable file or a shape it does not have.
    """
    data = _read_yaml(path, f'--params {path!r}')
    if isinstance(data, dict) and len(data) == 1:
        (inner,) = data.values()
        if isinstance(inner, dict) and isinstance(inner.get('ros__parameters'), dict):
            names = set(PIPELINE_FIELDS)
            return {k: v for k, v in inner['ros__parameters'].items() if k in names}
    if not isinstance(data, dict) or not all(isinstance(k, str) for k in data):
        raise ParamError(f'--params {path!r} must hold a mapping of setting: value (or a ROS '
                         f'params file of camera_node), got {type(data).__name__}.')
    return data


def default_markers() -> str:
    """The installed ``config/markers.yaml`` (or the source tree's, when not installed)."""
    return str(share_file('growspace_camera', 'config', 'markers.yaml'))


def load_layout(path: str = '') -> MarkerLayout:
    """Read a marker layout YAML (keys: dictionary, side_m, ids, centres_m).

    Raises:
        ParamError: naming the file and the key for a missing file, unknown keys or a bad
            value.
    """
    path = path or default_markers()
    return layout_from_dict(_read_yaml(path, f'markers = {path!r}'), path)


def load_lens(path: str) -> Lens:
    """Read a camera calibration YAML as ROS's camera_calibration writes it (and
    camera_info_manager reads it): ``image_width``, ``image_height``, ``camera_matrix`` and
    ``distortion_coefficients`` (each with ``data``), ``distortion_model`` ``plumb_bob`` or
    ``rational_polynomial``; other keys (rectification, projection) are not used.

    Raises:
        ParamError: naming the file and what is missing or wrong.
    """
    where = f'lens = {path!r}'
    data = _read_yaml(path, where)
    if not isinstance(data, dict):
        raise ParamError(f'{where}: needs a mapping of image_width, image_height, camera_matrix '
                         f'and distortion_coefficients, got a {type(data).__name__}.')
    model = data.get('distortion_model', 'plumb_bob')
    if model not in ('plumb_bob', 'rational_polynomial'):
        raise ParamError(f'{where}: distortion_model must be plumb_bob or rational_polynomial '
                         f"(OpenCV's pinhole model), got {model!r}.")
    try:
        return Lens(np.reshape(np.asarray(data['camera_matrix']['data'], float), (3, 3)),
                    np.asarray(data['distortion_coefficients']['data'], float),
                    (int(data['image_width']), int(data['image_height'])))
    except (KeyError, TypeError, ValueError) as e:
        raise ParamError(f'{where}: needs image_width, image_height, camera_matrix.data (9 '
                         f'numbers) and distortion_coefficients.data ({e}).') from None


def _read_yaml(path: str, what: str) -> Any:
    """A YAML file's data, or a ParamError that starts with ``what`` (the setting that named
    the file)."""
    try:
        with open(path, encoding='utf-8') as f:
            return yaml.safe_load(f)
    except OSError as e:
        raise ParamError(f'{what} cannot be read: {e.strerror or e}') from None
    except yaml.YAMLError as e:
        raise ParamError(f'{what} is not YAML: {e}') from None


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
