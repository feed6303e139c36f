"""The view image: a human-size, anti-aliased RGB picture of a ``Frame``, with a text overlay.

Unlike the 84 px observation (one entity per channel, for the agent), this is for people:
dark background, translucent light, yellow lit and grey dark photons, a red target, plants in
green with their segment thickness, and the challenge, step and reward in the top-left corner.
The chamber fills the image: ``size`` px for its width, the height in proportion, pixel (0, 0)
at the top-left (the chamber's top-left corner), as in ``sensor_msgs/Image``.
"""

from __future__ import annotations

import cv2
import numpy as np

from growspace_sim.ros import convert
from growspace_sim.view.scene import Frame

DEFAULT_SIZE = 512  # px
# BGR, as OpenCV draws; converted to RGB once at the end.
BACKGROUND = (28, 24, 22)
BEAM = (90, 230, 255)
BEAM_ALPHA = 0.22
TARGET = (60, 50, 235)
LIT = (60, 220, 255)
DARK = (110, 100, 95)
PLANT_COLOURS = ((70, 205, 50), (165, 165, 25), (40, 215, 140), (230, 140, 60))
TEXT = (240, 240, 240)
_SHIFT = 4  # cv2 fixed-point bits: sub-pixel positions


class ViewRenderer:
    """Draws frames at one size; keeps its canvases between calls.

    Args:
        size: image width in pixels (the chamber's width); 16 .. 4096.

    Raises:
        ValueError: a size out of range.
    """

    def __init__(self, size: int = DEFAULT_SIZE) -> None:
        if isinstance(size, bool) or not isinstance(size, int) or not 16 <= size <= 4096:
            raise ValueError(f'view_size must be an int in [16, 4096] px, got {size!r}.')
        self.size = size
        self._shape: tuple[int, int] | None = None

    def shape(self, frame: Frame) -> tuple[int, int]:
        """(height, width) in px of this frame's image."""
        cfg = frame.cfg
        return (max(1, round(self.size * cfg.chamber_height / cfg.chamber_width)), self.size)

    def render(self, frame: Frame, challenge: str | None = None) -> np.ndarray:
        """The (H, W, 3) uint8 RGB view image of ``frame``; a new array each call.

        Args:
            frame: what to draw.
            challenge: shown in the overlay; the frame's config's when None.
        """
        cfg = frame.cfg
        height, width = self.shape(frame)
        scale = width / cfg.chamber_width  # px per m, the same along x and z
        one = 1 << _SHIFT

        def px(x: np.ndarray | float, z: np.ndarray | float) -> tuple:
            # Pixel i covers [i, i + 1) and OpenCV addresses its centre i: hence the half.
            return (np.rint((np.asarray(x) * scale - 0.5) * one).astype(np.int64),
                    np.rint(((cfg.chamber_height - np.asarray(z)) * scale - 0.5) * one)
                    .astype(np.int64))

        image = np.empty((height, width, 3), np.uint8)
        image[:] = BACKGROUND
        self._light(image, frame, scale, px)
        if frame.photons is not None and frame.photons.size:
            cols, rows = px(frame.photons.real, frame.photons.imag)
            radius = max(1, round(0.004 * scale)) * one
            for c, r, lit in zip(cols.tolist(), rows.tolist(), frame.lit.tolist()):
                cv2.circle(image, (c, r), radius, LIT if lit else DARK, -1, cv2.LINE_AA,
                           _SHIFT)
        self._target(image, frame, scale, px)
        self._plants(image, frame, scale, px)
        self._overlay(image, frame, challenge or cfg.challenge)
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)  # OpenCV draws BGR; rgb8 is published

    @staticmethod
    def _light(image: np.ndarray, frame: Frame, scale: float, px) -> None:
        light = frame.light
        if light is None:
            return
        layer = image.copy()
        one = 1 << _SHIFT
        if int(light.mode) == convert.MODE_SPOT:
            c, r = px(float(light.x), float(light.z))
            cv2.circle(layer, (int(c), int(r)), int(round(float(light.radius) * scale * one)),
                       BEAM, -1, cv2.LINE_AA, _SHIFT)
        else:
            left = int(round((float(light.x) - 0.5 * float(light.width)) * scale))
            right = int(round((float(light.x) + 0.5 * float(light.width)) * scale))
            layer[:, max(left, 0):max(right, 0)] = BEAM
        cv2.addWeighted(layer, BEAM_ALPHA, image, 1.0 - BEAM_ALPHA, 0.0, dst=image)

    @staticmethod
    def _target(image: np.ndarray, frame: Frame, scale: float, px) -> None:
        cfg = frame.cfg
        if frame.target_mask is not None:
            mask = frame.target_mask.astype(np.uint8)
            big = cv2.resize(mask, (image.shape[1], image.shape[0]),
                             interpolation=cv2.INTER_NEAREST).astype(bool)
            image[big] = (0.5 * image[big] + 0.5 * np.array(TARGET)).astype(np.uint8)
        elif frame.target is not None:
            c, r = px(frame.target.real, frame.target.imag)
            radius = int(round(cfg.width_m(cfg.target_radius) * scale * (1 << _SHIFT)))
            cv2.circle(image, (int(c), int(r)), radius, TARGET, -1, cv2.LINE_AA, _SHIFT)

    @staticmethod
    def _plants(image: np.ndarray, frame: Frame, scale: float, px) -> None:
        child = np.flatnonzero(frame.parent >= 0)
        if child.size == 0:
            return
        parent = frame.parent[child]
        x0, z0 = px(frame.node_x[parent], frame.node_z[parent])
        x1, z1 = px(frame.node_x[child], frame.node_z[child])
        width = np.maximum(np.rint(frame.thickness[child] * scale), 1).astype(int)
        owner = frame.plant[child]
        # Thickest (oldest) segments first, so twigs stay visible where they join.
        order = np.argsort(-width, kind='stable')
        for i in order.tolist():
            cv2.line(image, (int(x0[i]), int(z0[i])), (int(x1[i]), int(z1[i])),
                     PLANT_COLOURS[int(owner[i]) % len(PLANT_COLOURS)], int(width[i]),
                     cv2.LINE_AA, _SHIFT)

    def _overlay(self, image: np.ndarray, frame: Frame, challenge: str) -> None:
        lines = (f'{challenge} ({frame.cfg.setting})', f'step {frame.step}',
                 f'reward {frame.reward:.3f}')
        font_scale = max(0.3, image.shape[1] / 1024)
        thickness = max(1, round(font_scale * 1.5))
        line_px = round(22 * font_scale * 1.4)
        for i, text in enumerate(lines):
            org = (round(8 * font_scale * 1.5), line_px * (i + 1))
            cv2.putText(image, text, org, cv2.FONT_HERSHEY_SIMPLEX, font_scale, (0, 0, 0),
                        thickness + 2, cv2.LINE_AA)  # an outline keeps it readable on light
            cv2.putText(image, text, org, cv2.FONT_HERSHEY_SIMPLEX, font_scale, TEXT,
                        thickness, cv2.LINE_AA)
