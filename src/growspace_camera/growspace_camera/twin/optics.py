"""What the camera adds to the light the plane sends it: lens distortion, vignetting and
sensor noise (the photo twin's optics, apart from what it draws on the plane)."""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from growspace_camera.lens import Lens

NOISE_SEED = 20_24  # the sensor noise bank's own seed (photos crop it at drawn offsets)


def calibration(k1: float, size: tuple[int, int]) -> Lens:
    """What calibrating the lens of ``distort`` gives, in OpenCV's model (as a rig's lens is
    calibrated once, with a chessboard): focal length half the diagonal, centre the photo's,
    and the radial coefficients of the inverse of ``distort``'s mapping (its series to r^7:
    0.8 px off at the corners of a 1920 x 1080 photo for k1 = -0.06).

    Args:
        k1: ``distort``'s coefficient.
        size: The photos' (width, height) [px].
    """
    w, h = size
    half = 0.5 * math.hypot(w, h)
    matrix = np.array([[half, 0.0, 0.5 * (w - 1)], [0.0, half, 0.5 * (h - 1)], [0.0, 0.0, 1.0]])
    return Lens(matrix, np.array([-k1, 3.0 * k1 ** 2, 0.0, 0.0, -12.0 * k1 ** 3]), (w, h))


def distort(photo: np.ndarray, k1: float) -> np.ndarray:
    """Radial lens distortion (k1 < 0 barrel, > 0 pincushion), on radii scaled by half the
    photo's diagonal."""
    h, w = photo.shape[:2]
    x = (np.arange(w, dtype=np.float32) - 0.5 * (w - 1))
    y = (np.arange(h, dtype=np.float32) - 0.5 * (h - 1))
    half = 0.5 * math.hypot(w, h)
    r2 = (x[None, :] ** 2 + y[:, None] ** 2) / half ** 2
    # The photo pixel at distorted radius r shows what the pinhole puts at r (1 + k1 r^2).
    gain = 1.0 + k1 * r2
    map_x = (x[None, :] * gain + 0.5 * (w - 1)).astype(np.float32)
    map_y = (y[:, None] * gain + 0.5 * (h - 1)).astype(np.float32)
    return cv2.remap(photo, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


@functools.cache
def _noise_bank(shape: tuple[int, ...]) -> np.ndarray:
    """Standard normal noise a little larger than a photo, drawn once per photo size (drawing
    6 million normals for every photo would cost more than everything else the twin does)."""
    h, w, c = shape
    bank = np.random.default_rng(NOISE_SEED).standard_normal((h + 64, w + 64, c), np.float32)
    bank.flags.writeable = False
    return bank


def noise(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """A photo's noise: a crop of the bank at a drawn offset, drawn flips and sign."""
    h, w = shape[:2]
    dy, dx = (int(v) for v in rng.integers(0, 65, 2))
    crop = _noise_bank(tuple(shape))[dy:dy + h, dx:dx + w]
    flip_rows, flip_cols, sign = (bool(v) for v in rng.integers(0, 2, 3))
    crop = crop[::-1] if flip_rows else crop
    crop = crop[:, ::-1] if flip_cols else crop
    return -crop if sign else crop


def vignette(size: tuple[int, int], strength: float) -> np.ndarray:
    w, h = size
    x = (np.arange(w, dtype=np.float32) - 0.5 * w) / (0.5 * w)
    y = (np.arange(h, dtype=np.float32) - 0.5 * h) / (0.5 * w)
    r2 = x[None, :] ** 2 + y[:, None] ** 2
    return 1.0 - strength * r2 / r2.max()
