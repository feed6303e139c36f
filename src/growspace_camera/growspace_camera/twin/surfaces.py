"""The surfaces behind the plant: the backdrop boards a rig may use, and the room around them
(the photo twin draws them on the plane canvas of ``CANVAS_M`` pixels)."""

from __future__ import annotations

import math

import cv2
import numpy as np

CANVAS_M = 0.001  # canvas pixel [m]: about one photo pixel at the default distance
BACKDROP_LEVEL = (190.0, 225.0)  # grey level of the backdrop under the photo light alone


def board(rng: np.random.Generator, x0: float, z0: float, x1: float,
              z1: float) -> np.ndarray:
    """A matte, slightly tinted board with low-frequency blotches and fine grain."""
    w = int(math.ceil((x1 - x0) / CANVAS_M))
    h = int(math.ceil((z1 - z0) / CANVAS_M))
    base = rng.uniform(*BACKDROP_LEVEL) * (1.0 + rng.uniform(-0.04, 0.04, 3))
    coarse = rng.standard_normal((h // 40 + 2, w // 40 + 2, 3)).astype(np.float32)
    coarse = base.astype(np.float32) * (1.0 + 0.05 * cv2.GaussianBlur(coarse, (0, 0), 1.0))
    board = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    grain = rng.standard_normal((h // 2 + 1, w // 2 + 1), dtype=np.float32) * 4.0
    board += cv2.resize(grain, (w, h), interpolation=cv2.INTER_LINEAR)[..., None]
    return np.clip(board, 0, 255, out=board).astype(np.uint8)


def room(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """What the photo shows around the backdrop: a dim, uneven room (float32 BGR)."""
    w, h = size
    grey = rng.uniform(30.0, 110.0, (6, 10, 1))
    coarse = (grey * rng.uniform(0.85, 1.15, (6, 10, 3))).astype(np.float32)  # dull colours
    return cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)


def rig_backdrop(rng: np.random.Generator, shape: tuple[int, ...],
                  kind: str) -> tuple[np.ndarray, float]:
    """A backdrop of another kind than the grey board; returns it and its brightest level.

    white: a near-white board; wood: plywood, warm, with grain along x; fabric: a tinted
    weave with folds; paint: a light wall with uneven coats and brush streaks.
    """
    h, w = shape[:2]

    def field(cells_m: float, amount: float) -> np.ndarray:  # smooth noise, +- amount
        ch, cw = int(h * CANVAS_M / cells_m) + 2, int(w * CANVAS_M / cells_m) + 2
        coarse = rng.standard_normal((ch, cw)).astype(np.float32)
        return amount * cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)

    if kind == 'white':
        base = rng.uniform(225.0, 245.0) * (1.0 + rng.uniform(-0.02, 0.02, 3))
        shade = 1.0 + field(0.05, 0.02)
    elif kind == 'wood':
        base = np.array([rng.uniform(95, 135), rng.uniform(150, 185), rng.uniform(195, 225)])
        rows = np.arange(h, dtype=np.float32)[:, None]
        period = rng.uniform(4.0, 14.0)  # mm between grain lines
        cols = np.arange(w, dtype=np.float32)[None, :]
        phase = field(0.04, 6.0) + cols * rng.uniform(-0.05, 0.05)  # wavy, slanted lines
        grain = np.sin(2 * np.pi * (rows + phase) / period)
        shade = 1.0 + rng.uniform(0.04, 0.12) * grain + field(0.1, 0.05)
    elif kind == 'fabric':
        tints = ((205, 215, 220), (215, 205, 190), (190, 200, 205), (200, 200, 200))
        base = np.array(tints[int(rng.integers(len(tints)))], float) * rng.uniform(0.85, 1.05)
        weave = rng.uniform(1.5, 3.0)  # mm
        y, x = np.mgrid[0:h, 0:w].astype(np.float32)
        shade = (1.0 + 0.04 * np.sin(2 * np.pi * x / weave) * np.sin(2 * np.pi * y / weave)
                 + field(0.12, 0.07))
    else:  # paint
        base = rng.uniform(200.0, 235.0) * (1.0 + rng.uniform(-0.03, 0.03, 3))
        streaks = cv2.resize(rng.standard_normal((8, w)).astype(np.float32), (w, h),
                             interpolation=cv2.INTER_LINEAR)
        shade = 1.0 + field(0.15, 0.06) + field(0.03, 0.02) + 0.02 * streaks
    board = shade[..., None].astype(np.float32) * np.asarray(base, np.float32)
    grain = rng.standard_normal((h // 2 + 1, w // 2 + 1), dtype=np.float32) * 3.0
    board += cv2.resize(grain, (w, h), interpolation=cv2.INTER_LINEAR)[..., None]
    return np.clip(board, 0, 255).astype(np.uint8), float(np.max(base))
