"""The light falling on the chamber's backdrop, divided out of a rectified photo (the flat
field of ``segment.plant_mask``): the white photo light, the grow lamp's coloured cast with
edges of any hardness, vignetting. Estimated away from the plant, from the backdrop alone.
"""

from __future__ import annotations

import cv2
import numpy as np

BACKDROP_KERNEL_M = 0.08  # the flat field averages the backdrop over this window [m]
EDGE_KERNEL_M = 0.04  # ... and then follows edges with a median over this window [m]
MEDIAN_SHRINK = 2  # the backdrop's wide mean runs on the chamber shrunk by this factor
# OpenCV's median is a sorting network up to 5 x 5 pixels and a histogram per pixel above,
# about ten times the cost: 3.7 ms for 9 x 9 on 176 x 176 BGR, 0.35 ms for 5 x 5. So the
# flat field's medians run on the chamber shrunk until their window is this many pixels.
MEDIAN_PX = 5
RATIO_SCALE = 128.0  # a photo-to-light ratio of 1 as uint8 (ratios up to 2 kept)
LIGHT_FLOOR = 0.35  # a light darker than this part of the backdrop's mean grey is no light
_SUM = np.array([[1.0, 1.0, 1.0]], np.float32)  # b + g + r


def flat_field(bgr: np.ndarray, exclude: np.ndarray, pixel_m: float,
               fill: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Divide out the light falling on the backdrop (``backdrop_light``, over the narrow
    ``EDGE_KERNEL_M`` window that follows lamp bands), estimated away from the plant.

    Args:
        bgr: (rows, cols, 3) float32 rectified photo.
        exclude: (rows, cols) bool, pixels that may be plant (left out of the estimate).
        pixel_m: Grid pixel [m].
        fill: (rows, cols, 3) float32, the light to assume where ``exclude`` is set.

    Returns:
        The photo as if lit evenly at its backdrop's mean grey level (float32), and that
        level; the photo as it is where nothing is backdrop.
    """
    light = backdrop_light(bgr, exclude, pixel_m, EDGE_KERNEL_M, fill)
    if light is None:
        return bgr, float(np.mean(cv2.mean(bgr)[:3]))
    # Back to the photo's grey levels, so that dark stays dark for ``greenness``.
    level = float(np.mean(cv2.mean(light)[:3]))
    return cv2.divide(bgr, light, scale=level), level


def backdrop_light(bgr: np.ndarray, exclude: np.ndarray, pixel_m: float, edge_m: float,
                   fill: np.ndarray | None = None, keep_edges: bool = True) -> np.ndarray | None:
    """The light falling on the backdrop, estimated away from the plant.

    The backdrop is neutral and everywhere behind the plant, so its local colour is the local
    light (the white photo light, the grow lamp's cast where it falls, vignetting). A mean
    over a window that straddles a lamp's hard edge (an LED bar's cut-off) would mix the
    light of both sides and leave a coloured line along the edge, which reads as a stem; so
    the light is the median of the backdrop over a window of ``edge_m`` (a median keeps a
    step where it is), with the pixels that may be plant first filled in from ``fill`` (an
    earlier estimate of the light) or a wide mean of the backdrop around them.

    Args:
        bgr: (rows, cols, 3) float32 rectified photo.
        exclude: (rows, cols) bool, pixels that may be plant (left out of the estimate).
        pixel_m: Grid pixel [m].
        edge_m: Side of the median window [m]: lamp bands narrower than half of it, and
            plant parts wider than half of it that ``exclude`` misses, are not followed.
        fill: (rows, cols, 3) float32, the light to assume where ``exclude`` is set.
        keep_edges: Keep a lamp's hard edge where it is (``_edge_keeping_median``); False:
            a coarse estimate (``_coarse_light``, on blocks, with ``fill`` unused), for a
            light that is only assumed behind the plant.

    Returns:
        The light (float32 BGR), or None where nothing is backdrop.
    """
    backdrop = (~exclude).view(np.uint8)
    if not backdrop.any():
        return None
    average = cv2.mean(bgr, backdrop)[:3]
    k = max(3, int(round(edge_m / pixel_m)) | 1)
    mean_px = max(3, int(round(BACKDROP_KERNEL_M / pixel_m)))
    if keep_edges:
        if not exclude.any():
            fill = bgr
        elif fill is None:
            fill = _backdrop_mean(bgr, backdrop, mean_px, average)
        filled = cv2.convertScaleAbs(bgr)  # uint8, saturated
        cv2.copyTo(cv2.convertScaleAbs(fill), exclude.view(np.uint8), filled)
        np.maximum(filled, 1, out=filled)
        light = _edge_keeping_median(filled, k)
    else:
        light = _coarse_light(bgr, backdrop, k, mean_px, average)
    # A backdrop is never lit this little (vignetting and a lamp's cast take a fraction of the
    # light, not nearly all of it): a light this dark follows a wide dark object (a cabinet
    # post, a pot, soil), and dividing by it would make that object's noise read as colour.
    # Such a light is brightened to the floor as a whole, its colour kept (raising only its
    # dark channels would give a dark, coloured object, a blue mesh, another colour).
    floor = LIGHT_FLOOR * float(np.mean(average))
    grey = cv2.transform(light, _SUM / 3.0)
    dim = grey < floor
    if dim.any():
        light[dim] *= (floor / np.maximum(grey[dim], 1.0))[:, None]
    return light


def _backdrop_mean(bgr: np.ndarray, backdrop: np.ndarray, k: int,
                   average: tuple[float, ...]) -> np.ndarray:
    """The mean of the ``backdrop`` (uint8 0/1) pixels of ``bgr`` over ``k`` x ``k`` pixels
    (float32 BGR), computed on the chamber shrunk by ``MEDIAN_SHRINK`` (a smooth estimate,
    only used where the plant may be); where a window holds (almost) no backdrop, the
    backdrop's ``average`` light stands in."""
    f = MEDIAN_SHRINK
    rows, cols = backdrop.shape
    lit, weight = _backdrop_blocks(bgr, backdrop, f)
    kc = (max(1, int(round(k / f))) | 1,) * 2
    weight, lit = cv2.blur(weight, kc), cv2.blur(lit, kc)
    mean = cv2.divide(lit, cv2.merge((np.maximum(weight, 1e-6),) * 3))
    mean[weight < 0.05] = average
    full = cv2.resize(mean, (mean.shape[1] * f, mean.shape[0] * f),
                      interpolation=cv2.INTER_LINEAR)
    return full[:rows, :cols]


def _backdrop_blocks(bgr: np.ndarray, backdrop: np.ndarray,
                     f: int) -> tuple[np.ndarray, np.ndarray]:
    """Per block of ``f`` x ``f`` pixels (the chamber ``_padded``): the mean of ``bgr`` over
    its ``backdrop`` (uint8 0/1) pixels times their share of it, and that share (float32)."""
    lit = np.zeros_like(bgr)
    cv2.copyTo(bgr, backdrop, lit)
    return (_shrunk(_padded(lit, f), f, cv2.INTER_AREA),
            _shrunk(_padded(backdrop.astype(np.float32), f), f, cv2.INTER_AREA))


def _padded(image: np.ndarray, f: int) -> np.ndarray:
    """``image`` padded (mirrored) at its bottom and right to whole multiples of ``f``."""
    rows, cols = image.shape[:2]
    pad_rows, pad_cols = -rows % f, -cols % f
    if pad_rows or pad_cols:
        image = cv2.copyMakeBorder(image, 0, pad_rows, 0, pad_cols, cv2.BORDER_REFLECT_101)
    return image


def _shrunk(image: np.ndarray, f: int, interpolation: int) -> np.ndarray:
    """A whole multiple of ``f`` in size (``_padded``), shrunk by ``f``."""
    return cv2.resize(image, (image.shape[1] // f, image.shape[0] // f),
                      interpolation=interpolation)


def _median(image: np.ndarray, k: int) -> np.ndarray:
    """OpenCV's ``k`` x ``k`` median with mirrored borders (``medianBlur`` repeats the edge
    row, and the chamber's bottom row may hold a little soil)."""
    h = k // 2
    return cv2.medianBlur(cv2.copyMakeBorder(image, h, h, h, h, cv2.BORDER_REFLECT_101),
                          k)[h:-h, h:-h]


def _shrink_for(k: int) -> int:
    """The factor that brings a ``k`` pixel window to about ``MEDIAN_PX`` pixels."""
    return max(1, int(round(k / MEDIAN_PX)))


def _coarse_light(bgr: np.ndarray, backdrop: np.ndarray, k: int, mean_px: int,
                  average: tuple[float, ...]) -> np.ndarray:
    """A median of about ``k`` x ``k`` pixels of the backdrop, computed on blocks shrunk to
    a ``MEDIAN_PX`` window (``_shrink_for``) and enlarged (float32 BGR): each block is the
    mean of its ``backdrop`` (uint8 0/1) pixels, or, where less than half of it is backdrop,
    of the backdrop within about ``mean_px`` of it (the backdrop's ``average`` where there is
    none). Only a guess at the light behind the plant: a lamp's edge is smoothed over a block.
    """
    rows, cols = backdrop.shape
    f = _shrink_for(k)
    lit, weight = _backdrop_blocks(bgr, backdrop, f)
    near = (max(1, int(round(mean_px / f))) | 1,) * 2
    wide_lit, wide_weight = cv2.blur(lit, near), cv2.blur(weight, near)
    own = weight >= 0.5
    lit[~own], weight[~own] = wide_lit[~own], wide_weight[~own]
    small = cv2.divide(lit, cv2.merge((np.maximum(weight, 1e-6),) * 3))
    small[weight < 0.05] = average
    np.maximum(small, 1.0, out=small)
    small = _median(small, MEDIAN_PX)  # (OpenCV's float median takes 3 or 5 pixels)
    full = cv2.resize(small, (small.shape[1] * f, small.shape[0] * f),
                      interpolation=cv2.INTER_LINEAR)
    return full[:rows, :cols]


def _edge_keeping_median(image: np.ndarray, k: int) -> np.ndarray:
    """A median of about ``k`` x ``k`` pixels of a uint8 BGR image, computed on the image
    shrunk to a ``MEDIAN_PX`` window (``_shrink_for``; float32): many times cheaper than at
    full size.

    Enlarged, the shrunk median would spread a hard lamp edge over a shrunk pixel or two (twin
    bench: IoU 0.92 -> 0.88 and refusals on hard-edged lamps). So the enlarged median is
    corrected at full size by the 5 x 5 median of the image's ratio to it (a step in the image
    is a step in the ratio, which a median keeps where it is), and the corrected value is held
    within the range of the shrunk median over its 3 x 3 neighbourhood: where the light is
    smooth that range is narrow, so a part of the plant that the exclusion missed is not
    taken for light; along a lamp's edge it spans both sides of the edge.
    """
    f = _shrink_for(k)
    rows, cols = image.shape[:2]
    image = _padded(image, f)
    small = _median(_shrunk(image, f, cv2.INTER_NEAREST), MEDIAN_PX)
    near = np.ones((3, 3), np.uint8)
    full = image.shape[1::-1]
    smooth = cv2.resize(small, full, interpolation=cv2.INTER_LINEAR)  # >= 1, as image is
    low = cv2.resize(cv2.erode(small, near), full, interpolation=cv2.INTER_LINEAR)
    high = cv2.resize(cv2.dilate(small, near), full, interpolation=cv2.INTER_LINEAR)
    # uint8 throughout (OpenCV saturates): the light to half a grey level.
    ratio = cv2.medianBlur(cv2.divide(image, smooth, scale=RATIO_SCALE), 5)
    light = cv2.multiply(ratio, smooth, scale=1.0 / RATIO_SCALE)
    light = cv2.min(cv2.max(light, low), high)
    return light[:rows, :cols].astype(np.float32)
