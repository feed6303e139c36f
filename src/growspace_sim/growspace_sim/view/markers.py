"""The chamber in 3D: a ``visualization_msgs/MarkerArray`` of a ``Frame``, for RViz and Foxglove.

Frame ``chamber`` (REP-103, metres, docs/recording.md): origin at the left end of the chamber
floor, x to the right along the light rail, z up, y = z x x (away from a viewer who sees x to
the right and z up). Plants, light and photons live in the plane y = 0.

Every frame sends the same (namespace, id) pairs, so a marker is replaced in place; what is not
known in a frame (photons of an episode the view cannot re-simulate, a light before the first
``light/state``) is sent as a DELETE of its id, so nothing stale stays on screen. The first
frame of an episode (step 0) starts with one DELETEALL.

| ns | id | type | what |
|---|---|---|---|
| ``chamber`` | 0 | LINE_STRIP | the chamber's walls, floor and ceiling |
| ``plant`` | plant index | TRIANGLE_LIST | each segment as two crossed ribbons of its thickness |
| ``light`` | 0 | CUBE / CYLINDER | translucent beam box, or the spotlight's disc |
| ``target`` | 0 | SPHERE / CUBE_LIST | target disc, or the digit's pixels (shape) |
| ``photons`` | 0, 1 | POINTS | lit photons, dark photons |
| ``status`` | 0 | TEXT_VIEW_FACING | challenge, step, reward above the chamber |

RViz draws triangle lists double-sided (no back-face culling), so the ribbons show from any side.
"""

from __future__ import annotations

from collections.abc import Sequence
import functools
import math
from typing import Any

import numpy as np

from growspace_sim.ros import convert
from growspace_sim.ros import types
from growspace_sim.view.scene import Frame

MARKER = 'visualization_msgs/msg/Marker'
MARKER_ARRAY = 'visualization_msgs/msg/MarkerArray'
ADD, DELETE, DELETEALL = 0, 2, 3
ARROW, CUBE, SPHERE, CYLINDER, LINE_STRIP = 0, 1, 2, 3, 4
CUBE_LIST, POINTS, TEXT_VIEW_FACING, TRIANGLE_LIST = 6, 8, 9, 11
FRAME_ID = 'chamber'
# RGBA in [0, 1]; plants cycle through these greens and teals.
PLANT_COLOURS = ((0.20, 0.80, 0.25, 1.0), (0.10, 0.65, 0.65, 1.0), (0.55, 0.85, 0.15, 1.0),
                 (0.25, 0.55, 0.90, 1.0))
WALL_COLOUR = (0.6, 0.6, 0.6, 1.0)
BEAM_COLOUR = (1.0, 0.95, 0.4, 0.25)  # translucent: the plant shows through
TARGET_COLOUR = (0.95, 0.15, 0.15, 0.9)
LIT_COLOUR = (1.0, 0.9, 0.2, 1.0)
DARK_COLOUR = (0.45, 0.45, 0.5, 1.0)
TEXT_COLOUR = (1.0, 1.0, 1.0, 1.0)
WALL_WIDTH = 0.004  # m, line width of the chamber outline
PHOTON_SIZE = 0.008  # m, side of a photon point
SPOT_DEPTH = 0.01  # m, thickness of the spotlight disc
TEXT_HEIGHT = 0.025  # m, height of a capital letter
# The spotlight disc faces the viewer: a cylinder's axis (z) turned onto y, -90 deg about x.
_Z_TO_Y = (-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))
_IDENTITY = (0.0, 0.0, 0.0, 1.0)
# Which (ns, id) every frame carries, in order after the optional DELETEALL.
FIXED_IDS = (('chamber', 0), ('light', 0), ('target', 0), ('photons', 0), ('photons', 1),
             ('status', 0))


@functools.cache
def _cls(typename: str) -> type:
    return types.msg_class(typename)


@functools.cache
def _empty() -> dict[str, Any]:
    """The unused Marker fields, shared by every marker (they are never modified)."""
    return {
        'lifetime': _cls('builtin_interfaces/msg/Duration')(sec=0, nanosec=0),
        'frame_locked': False,
        'colors': [],
        'texture_resource': '',
        'texture': types.new(types.COMPRESSED_IMAGE),
        'uv_coordinates': [],
        'mesh_resource': '',
        'mesh_file': types.new('visualization_msgs/msg/MeshFile'),
        'mesh_use_embedded_materials': False,
    }


def point(x: float, y: float, z: float) -> Any:
    return _cls('geometry_msgs/msg/Point')(x=x, y=y, z=z)


def points(xyz: np.ndarray) -> list[Any]:
    """``geometry_msgs/Point`` of each row of an (K, 3) array [m]."""
    cls = _cls('geometry_msgs/msg/Point')
    return [cls(x=x, y=y, z=z) for x, y, z in xyz.tolist()]


def colour(rgba: Sequence[float]) -> Any:
    return _cls('std_msgs/msg/ColorRGBA')(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def marker(header: Any, ns: str, marker_id: int, kind: int, *, action: int = ADD,
           position: Sequence[float] = (0.0, 0.0, 0.0),
           orientation: Sequence[float] = _IDENTITY,
           scale: Sequence[float] = (1.0, 1.0, 1.0), rgba: Sequence[float] = (1, 1, 1, 1),
           pts: list[Any] | None = None, text: str = '') -> Any:
    """One ``visualization_msgs/Marker`` (positions [m], orientation as x, y, z, w)."""
    pose = _cls('geometry_msgs/msg/Pose')(
        position=point(*position),
        orientation=_cls('geometry_msgs/msg/Quaternion')(
            x=orientation[0], y=orientation[1], z=orientation[2], w=orientation[3]))
    return _cls(MARKER)(
        header=header, ns=ns, id=marker_id, type=kind, action=action, pose=pose,
        scale=_cls('geometry_msgs/msg/Vector3')(x=scale[0], y=scale[1], z=scale[2]),
        color=colour(rgba), points=pts or [], text=text, **_empty())


def delete(header: Any, ns: str, marker_id: int) -> Any:
    return marker(header, ns, marker_id, ARROW, action=DELETE)


def marker_array(frame: Frame, frame_id: str = FRAME_ID, challenge: str | None = None) -> Any:
    """The ``visualization_msgs/MarkerArray`` of one frame.

    Args:
        frame: what to show (``Scene.on_result``).
        frame_id: the chamber frame of every marker.
        challenge: shown in the status text; the frame's config's challenge when None.

    Returns:
        The message: DELETEALL first on a reset frame, then ``FIXED_IDS`` and one plant marker
        per plant present.
    """
    header = convert.header(frame.stamp_ns, frame_id)
    cfg = frame.cfg
    out = [marker(header, '', 0, ARROW, action=DELETEALL)] if frame.reset else []
    out.append(_walls(header, cfg.chamber_width, cfg.chamber_height))
    out.append(_light(header, frame))
    out.append(_target(header, frame))
    out.extend(_photons(header, frame))
    out.append(_status(header, frame, challenge or cfg.challenge))
    out.extend(_plants(header, frame))
    return _cls(MARKER_ARRAY)(markers=out)


def _walls(header: Any, width: float, height: float) -> Any:
    corners = np.array([[0, 0, 0], [width, 0, 0], [width, 0, height], [0, 0, height],
                        [0, 0, 0]], np.float64)
    return marker(header, 'chamber', 0, LINE_STRIP, scale=(WALL_WIDTH, 0.0, 0.0),
                  rgba=WALL_COLOUR, pts=points(corners))


def _light(header: Any, frame: Frame) -> Any:
    light, cfg = frame.light, frame.cfg
    if light is None:
        return delete(header, 'light', 0)
    if int(light.mode) == convert.MODE_SPOT:
        d = 2.0 * float(light.radius)
        return marker(header, 'light', 0, CYLINDER, position=(light.x, 0.0, light.z),
                      orientation=_Z_TO_Y, scale=(d, d, SPOT_DEPTH), rgba=BEAM_COLOUR)
    height = cfg.chamber_height
    return marker(header, 'light', 0, CUBE, position=(light.x, 0.0, 0.5 * height),
                  scale=(light.width, beam_depth(cfg.chamber_width), height), rgba=BEAM_COLOUR)


def beam_depth(chamber_width: float) -> float:
    """Depth (along y) given to the beam box and the digit pixels [m]: a tenth of the width."""
    return 0.1 * chamber_width


def _target(header: Any, frame: Frame) -> Any:
    cfg = frame.cfg
    if frame.target_mask is not None:
        rows, cols = np.nonzero(frame.target_mask)
        n = frame.target_mask.shape[0]
        dx, dz = cfg.chamber_width / n, cfg.chamber_height / n
        xyz = np.column_stack(((cols + 0.5) * dx, np.zeros(cols.size),
                               cfg.chamber_height - (rows + 0.5) * dz))
        return marker(header, 'target', 0, CUBE_LIST, scale=(dx, 0.5 * dx, dz),
                      rgba=TARGET_COLOUR, pts=points(xyz))
    if frame.target is None:
        return delete(header, 'target', 0)
    d = 2.0 * cfg.width_m(cfg.target_radius)
    position = (frame.target.real, 0.0, frame.target.imag)
    return marker(header, 'target', 0, SPHERE, position=position, scale=(d, d, d),
                  rgba=TARGET_COLOUR)


def _photons(header: Any, frame: Frame) -> list[Any]:
    if frame.photons is None:
        return [delete(header, 'photons', 0), delete(header, 'photons', 1)]
    out = []
    for marker_id, chosen, rgba in ((0, frame.lit, LIT_COLOUR), (1, ~frame.lit, DARK_COLOUR)):
        p = frame.photons[chosen]
        xyz = np.column_stack((p.real, np.zeros(p.size), p.imag))
        out.append(marker(header, 'photons', marker_id, POINTS,
                          scale=(PHOTON_SIZE, PHOTON_SIZE, 0.0), rgba=rgba, pts=points(xyz)))
    return out


def _status(header: Any, frame: Frame, challenge: str) -> Any:
    cfg = frame.cfg
    text = f'{challenge} {cfg.setting}  step {frame.step}  reward {frame.reward:.3f}'
    return marker(header, 'status', 0, TEXT_VIEW_FACING,
                  position=(0.5 * cfg.chamber_width, 0.0, cfg.chamber_height + 2 * TEXT_HEIGHT),
                  scale=(0.0, 0.0, TEXT_HEIGHT), rgba=TEXT_COLOUR, text=text)


def ribbons(frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """Triangle vertices of every segment: two crossed quads of the segment's thickness.

    Returns:
        (12 K, 3) float64 vertices [m], 4 triangles per segment (one quad in the x-z plane,
        one across it along y), and the (K,) plant of each segment.
    """
    child = np.flatnonzero(frame.parent >= 0)
    a = np.column_stack((frame.node_x, frame.node_z))[frame.parent[child]]
    b = np.column_stack((frame.node_x, frame.node_z))[child]
    length = np.hypot(*(b - a).T)
    keep = length > 0.0
    child, a, b, length = child[keep], a[keep], b[keep], length[keep]
    half = 0.5 * frame.thickness[child]
    d = (b - a) / length[:, None]
    n = np.column_stack((-d[:, 1], d[:, 0])) * half[:, None]  # across, in the x-z plane
    zero = np.zeros_like(half)

    def xyz(xz: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.column_stack((xz[:, 0], y, xz[:, 1]))

    front = (xyz(a + n, zero), xyz(a - n, zero), xyz(b - n, zero), xyz(b + n, zero))
    side = (xyz(a, half), xyz(a, -half), xyz(b, -half), xyz(b, half))
    quads = []
    for p0, p1, p2, p3 in (front, side):
        quads += [p0, p1, p2, p0, p2, p3]
    vertices = np.stack(quads, axis=1).reshape(-1, 3)  # segment-major: 12 rows per segment
    return vertices, frame.plant[child]


def _plants(header: Any, frame: Frame) -> list[Any]:
    vertices, owner = ribbons(frame)
    out = []
    for p in np.unique(frame.plant).tolist():
        rows = np.repeat(owner == p, 12)
        if not rows.any():  # a bare root: RViz flags a TRIANGLE_LIST without points
            out.append(delete(header, 'plant', p))
            continue
        # Scale 1: RViz scales a TRIANGLE_LIST's vertices by it (and warns about a 0).
        out.append(marker(header, 'plant', p, TRIANGLE_LIST, scale=(1.0, 1.0, 1.0),
                          rgba=PLANT_COLOURS[p % len(PLANT_COLOURS)],
                          pts=points(vertices[rows])))
    return out
