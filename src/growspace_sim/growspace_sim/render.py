"""Observation images of a chamber: the only module that draws, kept apart from the core.

The image is RGB with one entity per channel, so nothing hides anything else:
red = target (disc or digit), green = plant, blue = light. Pixel (0, 0) is the top-left corner
(as in ``sensor_msgs/Image``): column = x / width * size, row = (height - z) / height * size.
The plant is drawn incrementally (segments only ever appear or thicken), so a step draws only
what changed: OpenCV draws lines and discs on one plane per entity, and the RGB image is kept up
to date channel by channel (a beam's move rewrites only the columns it left or entered). Finding
the segments to draw and copying planes into channels are small numba kernels (compiled once,
then loaded from numba's on-disk cache).
"""

from __future__ import annotations

import cv2
from numba import njit
import numpy as np

from growspace_sim.core.chamber import Chamber
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import Light

TARGET, PLANT, LIGHT = 0, 1, 2  # channel of each entity
INTENSITY = (255, 255, 128)  # the light is dimmer so the image reads like the paper's
_SHIFT = 4  # cv2 fixed-point bits: sub-pixel endpoints, integer arithmetic, same bytes everywhere


class Renderer:
    """Draws one chamber's observation; call ``reset`` after each ``Chamber.reset``."""

    def __init__(self, cfg: SimConfig) -> None:
        self.cfg = cfg
        self.size = cfg.resolution
        self._px_per_m = self.size / cfg.chamber_width
        self._rows_per_m = self.size / cfg.chamber_height
        self._plant = np.zeros((self.size, self.size), np.uint8)
        self._light = np.zeros((self.size, self.size), np.uint8)
        self._target = np.zeros((self.size, self.size), np.uint8)
        # col = x * px_per_m - 0.5 and row = (height - z) * rows_per_m - 0.5, in 1/16 px:
        # pixel i covers [i, i + 1) and OpenCV addresses its centre i, hence the half pixel.
        one = 1 << _SHIFT
        self._fixed_scale = (self._px_per_m * one, -self._rows_per_m * one)
        self._fixed_offset = (-0.5 * one, (cfg.chamber_height * self._rows_per_m - 0.5) * one)
        self._drawn_nodes = -1
        self._drawn_light: tuple[float, ...] | None = None
        self._image = np.zeros((self.size, self.size, 3), np.uint8)  # the planes, interleaved
        self._band = np.zeros(2, np.int64)  # the beam's columns [left, right) in the image
        self._drawn_px = np.zeros(0, np.int32)
        self._px_for_descendants = np.zeros(0, np.int32)
        self._segments = np.zeros((0, 5), np.int64)  # to draw: start col, row, end col, row, px
        self._box = np.zeros(4, np.int64)  # rows [0, 1) and columns [2, 3) they can reach

    def reset(self, chamber: Chamber) -> None:
        """Forget the previous episode and draw the new target."""
        self._plant.fill(0)
        self._target.fill(0)
        if chamber.target_mask is not None:
            self._target[chamber.target_mask] = INTENSITY[TARGET]
        elif chamber.target is not None:  # a task may have no target at all (Layout)
            radius = chamber.cfg.width_m(chamber.cfg.target_radius)
            cv2.circle(self._target, self._fixed_point(chamber.target), self._fixed(radius),
                       INTENSITY[TARGET], -1, cv2.LINE_8, _SHIFT)
        self._image.fill(0)
        _put_channel(self._target, self._image, TARGET, 0, self.size, 0, self.size)
        self._band[:] = 0
        self._drawn_nodes = -1  # force a full plant and light draw
        self._drawn_light = None
        self._drawn_px = np.zeros(chamber.pos.size, np.int32)
        if self._segments.shape[0] != chamber.pos.size:
            self._segments = np.zeros((chamber.pos.size, 5), np.int64)
        # Pixel thickness for every possible descendant count, so a step only looks it up.
        base = chamber.thickness_for(np.arange(chamber.pos.size + 1))
        self._px_for_descendants = np.maximum(np.rint(base * self._px_per_m), 1).astype(np.int32)

    def render(self, chamber: Chamber, out: np.ndarray | None = None) -> np.ndarray:
        """The observation (size, size, 3) uint8 RGB: a new array, or written into ``out``."""
        if chamber.n_nodes != self._drawn_nodes:  # the plant only changes when it grows
            self._draw_plant(chamber)
            self._drawn_nodes = chamber.n_nodes
        light = chamber.state.light
        placement = (light.x, light.z, light.width, light.radius)
        if placement != self._drawn_light:
            self._draw_light(light)
            self._drawn_light = placement
        if out is None:
            return self._image.copy()
        out[...] = self._image
        return out

    def features(self, chamber: Chamber) -> np.ndarray:
        """The same scene as binary feature maps (size, size, 3) uint8 in {0, 1}."""
        return (self.render(chamber) > 0).view(np.uint8)

    def _draw_plant(self, chamber: Chamber) -> None:
        if chamber.target_mask is not None:  # shape: exactly the pixels the reward counts
            self._plant[chamber.occupancy] = INTENSITY[PLANT]
            _put_channel(self._plant, self._image, PLANT, 0, self.size, 0, self.size)
            return
        scale, offset, box = self._fixed_scale, self._fixed_offset, self._box
        count = _segments_to_draw(chamber.descendants, chamber.cfg.plant_count,
                                  self._px_for_descendants, self._drawn_px, chamber.pos,
                                  chamber.parent, scale[0], scale[1], offset[0], offset[1],
                                  self._segments, box)
        for x0, y0, x1, y1, width in self._segments[:count].tolist():
            cv2.line(self._plant, (x0, y0), (x1, y1), INTENSITY[PLANT], width, cv2.LINE_8,
                     _SHIFT)
        if count:  # only the pixels the lines can have reached
            _put_channel(self._plant, self._image, PLANT, box[0], box[1], box[2], box[3])

    def _draw_light(self, light: Light) -> None:
        if light.spot:
            self._light.fill(0)  # 7 kB: cheaper than working out what changed
            cv2.circle(self._light, self._fixed_point(complex(light.x, light.z)),
                       self._fixed(light.radius), INTENSITY[LIGHT], -1, cv2.LINE_8, _SHIFT)
            _put_channel(self._light, self._image, LIGHT, 0, self.size, 0, self.size)
        else:  # full-height columns: the plane stays empty
            _move_band(self._image, self._band, light.x, light.width, self._px_per_m)

    def _fixed_point(self, p: complex) -> tuple[int, int]:
        """OpenCV fixed-point (col, row) of a chamber point (complex, m)."""
        scale, offset = self._fixed_scale, self._fixed_offset
        return (round(p.real * scale[0] + offset[0]), round(p.imag * scale[1] + offset[1]))

    def _fixed(self, metres: float) -> int:
        return int(round(metres * self._px_per_m * (1 << _SHIFT)))


@njit(cache=True)
def _segments_to_draw(descendants: np.ndarray, roots: int, px_for_descendants: np.ndarray,
                      drawn_px: np.ndarray, pos: np.ndarray, parent: np.ndarray,
                      scale_x: float, scale_y: float, offset_x: float, offset_y: float,
                      out: np.ndarray, box: np.ndarray) -> int:
    """List the segments that are new or thicker than drawn (roots come first, with none).

    Returns:
        How many: rows of ``out`` = OpenCV fixed-point start (col, row), end (col, row) and
        thickness in px; ``drawn_px`` records the new thicknesses and ``box`` the pixel rows
        [box[0], box[1]) and columns [box[2], box[3]) that drawing them can change.
    """
    count = 0
    box[0], box[1], box[2], box[3] = 1 << 30, -(1 << 30), 1 << 30, -(1 << 30)
    for node in range(roots, descendants.size):
        px = px_for_descendants[descendants[node]]
        if px <= drawn_px[node]:
            continue
        drawn_px[node] = px
        start, end = pos[parent[node]], pos[node]
        out[count, 0] = round(start.real * scale_x + offset_x)  # half to even, as Python's
        out[count, 1] = round(start.imag * scale_y + offset_y)
        out[count, 2] = round(end.real * scale_x + offset_x)
        out[count, 3] = round(end.imag * scale_y + offset_y)
        out[count, 4] = px
        margin = px + 2  # a thick line reaches half its thickness around it; generously
        box[0] = min(box[0], (min(out[count, 1], out[count, 3]) >> _SHIFT) - margin)
        box[1] = max(box[1], (max(out[count, 1], out[count, 3]) >> _SHIFT) + margin + 1)
        box[2] = min(box[2], (min(out[count, 0], out[count, 2]) >> _SHIFT) - margin)
        box[3] = max(box[3], (max(out[count, 0], out[count, 2]) >> _SHIFT) + margin + 1)
        count += 1
    return count


@njit(cache=True)
def _put_channel(plane: np.ndarray, image: np.ndarray, channel: int, top: int, bottom: int,
                 left: int, right: int) -> None:
    """Copy rows [top, bottom) x columns [left, right) of an (H, W) plane (clipped to it) into
    one channel of an (H, W, 3) image."""
    rows, cols = plane.shape
    for r in range(max(top, 0), min(bottom, rows)):
        for c in range(max(left, 0), min(right, cols)):
            image[r, c, channel] = plane[r, c]


@njit(cache=True)
def _move_band(image: np.ndarray, band: np.ndarray, x: float, width: float,
               px_per_m: float) -> None:
    """Light the beam's columns (centre x, width in m) in the blue channel, rewriting only the
    columns that change from ``band`` (the lit [left, right) so far, updated)."""
    cols = image.shape[1]
    left = max(round((x - 0.5 * width) * px_per_m), 0)  # half to even, as Python's round
    right = min(max(round((x + 0.5 * width) * px_per_m), 0), cols)
    for c in range(min(band[0], left), max(band[1], right)):
        lit = left <= c < right
        if lit != (band[0] <= c < band[1]):
            for r in range(image.shape[0]):
                image[r, c, LIGHT] = INTENSITY[LIGHT] if lit else 0
    band[0], band[1] = left, right
