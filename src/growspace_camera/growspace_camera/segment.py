"""Photo -> plant mask on the chamber plane: exposure checks, rectification, greenness, Otsu.

Each step is a plain function of arrays (PlantCV's way): ``exposure`` reads the photo's grey
levels, ``rectify`` warps the chamber square of the photo to a top-left-origin grid of the
plane (``Grid``), ``flatfield.flat_field`` divides out the light falling on the backdrop (the
grow lamp's coloured cast, vignetting), ``greenness`` is the excess-green index
ExG = 2g - r - b on chromatic coordinates (Woebbecke et al. 1995), and ``plant_mask``
thresholds it with Otsu's method, floored so that a plant-free photo stays empty, then cleans
the mask up."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from growspace_camera.calibration import PlaneFit
from growspace_camera.errors import CameraError, EXPOSURE
from growspace_camera.flatfield import backdrop_light, flat_field

SATURATED = 250  # grey level from which a pixel counts as clipped
EXG_SCALE = 255.0 / 1.5  # ExG in [-1, 2] -> uint8 for OpenCV's Otsu: (ExG + 0.5) x scale
WIDE_KERNEL_M = 0.12  # the first estimate's median window, wider than twice any stem [m]
SEED_GREENNESS = 0.12  # a region is plant only where some pixel is this green (ExG), at least
DIM = 0.08  # a pixel darker than this part of the backdrop's grey level has no colour
FLOOD_FRACTION = 0.25  # a greener region larger than this part of the chamber is light ...
FLOOD_FILL = 0.6  # ... if it fills this much of its bounding box (a band, not a tree)
NOISE_SIGMAS = 6.0  # greenness this far above the backdrop's noise is plant, whatever Otsu says
WARM_FROM = 0.015  # warmth (``tissue``) below which a dark pixel is not bark at all
WARM = 0.04  # ... and from which, this much above, it counts fully as bark
BARK_DILUTION = 0.5  # the constant in the warmth's sum, in backdrop grey levels
BROWN_WEIGHT = 0.6  # a bark pixel's tissue index per unit of darkness
STRIP_FRACTION = 0.5  # a mask column this full of photo-grey pixels is an unlit strip
FLOOR_M = 0.005  # the grid's rows this close to the soil line are checked against those above
PALE = 0.5  # a gap in a plant is bridged through pixels down to this part of ``min_greenness``
MAX_GAP_M = 0.01  # ... when the gap is at most this long [m]
_SUM = np.array([[1.0, 1.0, 1.0]], np.float32)  # b + g + r
_EXCESS_GREEN = np.array([[-1.0, 2.0, -1.0]], np.float32)  # 2g - r - b (BGR order)
_WARMTH = np.array([[-1.0, 0.0, 1.0]], np.float32)  # r - b
_YELLOWNESS = np.array([[-4.0, 4.0, 0.0]], np.float32)  # 4 (g - b)


@dataclass(frozen=True)
class SegmentParams:
    """What the segmentation accepts (ROS parameters of camera_node, same names).

    Attributes:
        pixel_m: Side of a rectified pixel on the plant plane [m].
        min_greenness: Lowest ExG threshold, whatever Otsu finds (keeps an empty pot empty).
        min_contrast: Mean ExG of plant minus backdrop below which nothing counts as plant.
        min_area_m2: Smaller specks are not plant [m^2].
        dark_level: A photo whose mean grey level is below this is too dark [0-1].
        max_saturated: A photo with more clipped pixels than this is overexposed [0-1].
    """

    pixel_m: float = 0.0025
    min_greenness: float = 0.06
    min_contrast: float = 0.08
    min_area_m2: float = 0.0001
    dark_level: float = 0.08
    max_saturated: float = 0.2


@dataclass(frozen=True)
class Grid:
    """The rectified plane: pixel (row, column) centre <-> chamber (x, z) [m]; row 0 on top."""

    width_m: float
    height_m: float
    pixel_m: float

    @property
    def shape(self) -> tuple[int, int]:
        return (int(round(self.height_m / self.pixel_m)), int(round(self.width_m / self.pixel_m)))

    def to_plane(self) -> np.ndarray:
        """(3, 3) grid (column, row, 1) -> chamber (x, z, 1)."""
        s, h = self.pixel_m, self.shape[0] * self.pixel_m
        return np.array([[s, 0.0, 0.5 * s], [0.0, -s, h - 0.5 * s], [0.0, 0.0, 1.0]])

    def xz(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(N, 2) chamber (x, z) [m] of grid pixel centres."""
        s, h = self.pixel_m, self.shape[0] * self.pixel_m
        return np.column_stack(((np.asarray(cols) + 0.5) * s, h - (np.asarray(rows) + 0.5) * s))


@dataclass(frozen=True)
class Exposure:
    """How the photo is exposed: mean grey level and clipped fraction [0-1]."""

    mean: float
    saturated: float


@dataclass
class Segmentation:
    """A plant mask on the grid, and how sure it is.

    Attributes:
        mask: (rows, cols) bool, True = plant.
        threshold: The ExG threshold used (Otsu's, or the floor).
        contrast: Mean ExG of the plant pixels minus that of the rest.
        specks: Pixels removed as specks (components smaller than ``min_area_m2``).
        coverage: (rows, cols) float32 in [0, 1], how much of each pixel next to or in the
            mask the plant covers (its greenness between the backdrop's and the nearby
            stem's); 0 elsewhere. Edges blurred by the lens and the warp stay symmetric
            about a stem's axis in it, so centroids on it place a stem to a fraction of a
            pixel.
    """

    mask: np.ndarray
    threshold: float
    contrast: float
    specks: int
    coverage: np.ndarray | None = None


def exposure(gray: np.ndarray, params: SegmentParams) -> Exposure:
    """Check a photo's exposure.

    Raises:
        CameraError: ``EXPOSURE`` for a photo too dark or too clipped to read.
    """
    mean = float(gray.mean()) / 255.0
    saturated = float(np.count_nonzero(gray >= SATURATED)) / gray.size
    if mean < params.dark_level:
        raise CameraError(EXPOSURE, f'the photo is too dark: mean grey level {mean:.3f} < '
                          f'dark_level {params.dark_level} (lamp or photo light off, lens '
                          f'covered, exposure too short)')
    if saturated > params.max_saturated:
        raise CameraError(EXPOSURE, f'the photo is overexposed: {saturated:.0%} of it is '
                          f'clipped > max_saturated {params.max_saturated:.0%} (exposure too '
                          f'long, gain too high)')
    return Exposure(mean, saturated)


def rectify(photo: np.ndarray, fit: PlaneFit, grid: Grid) -> np.ndarray:
    """The grid's view of the plane, warped from the photo (float32 BGR).

    The photo's chamber region is first shrunk (area interpolation, by a whole factor) to one
    photo pixel or a little more per grid pixel, so the warp samples without aliasing. With a
    calibrated lens, the warp samples through its distortion (``Lens.sample_maps``).
    """
    rows, cols = grid.shape
    # The grid's outline in the photo (its corners and sides: a barrel lens bows the sides).
    along, low = np.linspace(0.0, 1.0, 5), np.zeros(5)
    side_rows = np.r_[along, along, low, low + 1.0] * (rows - 1)
    side_cols = np.r_[low, low + 1.0, along, along] * (cols - 1)
    corners = fit.photo_points(grid.xz(side_rows, side_cols))
    h, w = photo.shape[:2]
    left, top = np.floor(np.clip(corners.min(axis=0) - 4, 0, [w - 1, h - 1])).astype(int)
    right, bottom = np.ceil(np.clip(corners.max(axis=0) + 5, 1, [w, h])).astype(int)
    # An integer factor, the largest that keeps a photo pixel or more per grid pixel: OpenCV's
    # area shrink is then a plain block mean, several times faster than a fractional one.
    factor = max(1, int(grid.pixel_m * fit.px_per_m((0.5 * grid.width_m, 0.5 * grid.height_m))))
    right -= (right - left) % factor
    bottom -= (bottom - top) % factor
    crop = photo[top:bottom, left:right]
    if factor > 1:
        crop = cv2.resize(crop, ((right - left) // factor, (bottom - top) // factor),
                          interpolation=cv2.INTER_AREA)
    sy = sx = 1.0 / factor
    # grid pixel -> plane -> photo -> crop -> shrunk crop (pixel centres throughout)
    shrink = np.array([[sx, 0.0, 0.5 * sx - 0.5 - left * sx],
                       [0.0, sy, 0.5 * sy - 0.5 - top * sy], [0.0, 0.0, 1.0]])
    to_photo = fit.to_photo @ grid.to_plane()
    if fit.lens is None:
        out = cv2.warpPerspective(crop, shrink @ to_photo, (cols, rows),
                                  flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                  borderMode=cv2.BORDER_REPLICATE)
    else:
        map_x, map_y = fit.lens.sample_maps(to_photo, (cols, rows), shrink)
        out = cv2.remap(crop, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.astype(np.float32)


def greenness(bgr: np.ndarray) -> np.ndarray:
    """Excess green ExG = 2g - r - b of chromatic coordinates (c / (b + g + r)), float32.

    A small constant in the sum keeps dark pixels from getting a loud, noisy chromaticity.
    """
    total = cv2.transform(bgr, _SUM)
    total += 30.0
    return cv2.divide(cv2.transform(bgr, _EXCESS_GREEN), total)


def tissue(bgr: np.ndarray, level: float, green: np.ndarray | None = None) -> np.ndarray:
    """How much each pixel of an evenly lit photo looks like plant tissue, green or brown.

    Green tissue: excess green (``greenness``, or ``green`` if given). Brown, woody tissue is
    not greener than the backdrop, but it is darker and warm: red above green above blue
    (bark's hue, 15-50 degrees). Its warmth is r - b, or 4 (g - b) where that is less (a
    purple or magenta pixel, g below b, is not bark), on chromatic coordinates whose sum
    carries half a backdrop grey level of constant (``BARK_DILUTION``): the few grey levels by
    which the channels of a black post, a pot or dark soil differ (noise, JPEG, a tint) must
    not make it warm. Tissue counts fully once that warmth reaches ``WARM`` above
    ``WARM_FROM``, times its darkness below the backdrop's ``level``. A neutral dark pixel
    (wood grain, a shadow, a fold) is not warm, so it stays low. ``plant_mask`` keeps brown
    tissue only where it joins green tissue.
    """
    exg = greenness(bgr) if green is None else green
    total = cv2.transform(bgr, _SUM)
    hue_warmth = cv2.min(cv2.transform(bgr, _WARMTH), cv2.transform(bgr, _YELLOWNESS))
    level = max(level, 1.0)
    warm = cv2.divide(hue_warmth, total + BARK_DILUTION * level, scale=1.0 / WARM)
    warm -= WARM_FROM / WARM
    dark = cv2.addWeighted(total, -BROWN_WEIGHT / (3.0 * level), total, 0.0, BROWN_WEIGHT)
    brown = cv2.multiply(_unit(warm), _unit(dark, BROWN_WEIGHT))
    return cv2.max(exg, brown)


def _unit(x: np.ndarray, top: float = 1.0) -> np.ndarray:
    """``x`` clipped to [0, top] in place (a single-channel float32 image)."""
    cv2.threshold(x, top, top, cv2.THRESH_TRUNC, dst=x)  # (a quarter of numpy's time)
    return cv2.threshold(x, 0.0, 0.0, cv2.THRESH_TOZERO, dst=x)[1]


def plant_mask(bgr: np.ndarray, params: SegmentParams, ground_m: float = 0.03) -> Segmentation:
    """The plant's pixels in a rectified photo: balance, flat field, ExG, Otsu, clean-up.

    A chamber with a colour clipped in more than ``max_saturated`` of it is refused: where a
    channel is clipped, the flat field cannot take the lamp's colour out, and a green stem
    under a magenta lamp would read as brown.

    A first, rough threshold finds what to leave out of the flat field; the second runs on
    the flat-fielded photo. The threshold is Otsu's, but never below ``min_greenness``;
    pixels down to half of it are kept where they join a pixel above it (hysteresis: thin
    twig ends are paler than stems). When the plant stands out from the backdrop by less than
    ``min_contrast``, nothing is plant (an empty pot must not become a plant of noise). A
    piece of plant cut off from the rest by a stretch paler than that is joined back
    (``_bridge``); a piece reaching within ``ground_m`` of the soil line (the skeleton's base
    band) may stand on it, so it is never joined to another such piece.
    """
    # (``inRange`` counts the pixels with every colour below SATURATED: a tenth of the time of
    # a per-pixel maximum)
    below = float(np.nextafter(np.float32(SATURATED), np.float32(0.0)))
    clipped = 1.0 - cv2.countNonZero(cv2.inRange(bgr, (-np.inf,) * 3, (below,) * 3)) \
        / (bgr.shape[0] * bgr.shape[1])
    if clipped > params.max_saturated:
        raise CameraError(EXPOSURE, f'the chamber is overexposed: a colour is clipped in '
                          f'{clipped:.0%} of it > max_saturated {params.max_saturated:.0%} '
                          '(the light of the lamp at this exposure? shorten exposure)')
    # The backdrop fills most of the chamber: its median colour balances the photo first,
    # so that a tinted backdrop or white balance cannot pass for green.
    balance = np.median(bgr[::3, ::3].reshape(-1, 3), axis=0)
    gain = float(balance.mean()) / np.maximum(balance, 1.0)
    bgr = cv2.transform(bgr, np.diag(gain).astype(np.float32))
    first = greenness(bgr)
    rough = first > max(_otsu(first), params.min_greenness)
    # Bark too: a trunk that is wide low down (wider than half the flat field's window) and
    # brown, which greenness misses, would otherwise be taken for the light and divided away.
    bark = tissue(bgr, float(balance.mean()), np.zeros_like(first))
    rough = (rough | (bark > max(_otsu(bark), params.min_greenness))).view(np.uint8)
    rough = _without_floods(cv2.dilate(rough, np.ones((5, 5), np.uint8)).view(bool))
    # Two medians: a wide one gives the light to assume behind what may be plant (a thick
    # trunk is less than half of its window; coarse, as only a guess behind the plant needs
    # to be), a narrow one follows the lamp's bands and edges. What only
    # the wide one's division shows as tissue is not left out of the narrow one: that is
    # mostly the backdrop between lamp bands, which the wide median did not follow.
    light = backdrop_light(bgr, rough, params.pixel_m, WIDE_KERNEL_M, keep_edges=False)
    flat, level = flat_field(bgr, rough, params.pixel_m, fill=light)
    flat = cv2.GaussianBlur(flat, (3, 3), 0)
    green = greenness(flat)
    exg = tissue(flat, level, green)
    # A pixel this dark in the photo has no colour to read (sensor noise, JPEG, the tint of a
    # black cabinet post): whatever the flat field makes of it, it is not tissue.
    grey = cv2.GaussianBlur(cv2.transform(bgr, _SUM), (3, 3), 0)
    dim = (grey < 3.0 * DIM * float(balance.mean())).view(np.uint8)
    cv2.copyTo(np.minimum(exg, 0.0), dim, exg)
    _floor_rows(exg, params.pixel_m)
    centre = float(np.median(exg[::3, ::3]))  # the backdrop's
    noise = _noise(exg, centre)
    threshold = _plant_threshold(exg, params.min_greenness, centre, noise)
    low = max(0.5 * threshold, params.min_greenness)
    # Seeds are green: brown tissue is plant where it joins green tissue (a woody stem carries
    # the shoot's leaves), while a warm, dark cabinet post, pot rim or mesh on its own is not.
    mask = _hysteresis(exg, low, threshold, green, SEED_GREENNESS)
    mask[_unlit_strips(mask.view(bool) & ~rough)] = 0
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    min_px = params.min_area_m2 / params.pixel_m ** 2
    pale = max(PALE * params.min_greenness, centre + NOISE_SIGMAS * noise)
    if pale < low:
        _bridge(mask, exg, pale, min_px, int(np.ceil(ground_m / params.pixel_m)),
                int(round(MAX_GAP_M / params.pixel_m)))
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    small = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] < min_px) + 1
    specks = int(stats[small, cv2.CC_STAT_AREA].sum())
    keep = np.ones(count, bool)
    keep[0] = False
    keep[small] = False
    plant = keep[labels]
    inside = plant.astype(np.uint8)
    contrast = cv2.mean(exg, inside)[0] - cv2.mean(exg, 1 - inside)[0] if inside.any() else 0.0
    if contrast < params.min_contrast:
        plant[:] = False
    return Segmentation(plant, float(threshold), contrast, specks,
                        _coverage(exg, plant, centre))


def _without_floods(rough: np.ndarray) -> np.ndarray:
    """A rough mask less its regions wider than ``FLOOD_FRACTION`` of the chamber that fill
    ``FLOOD_FILL`` of their bounding box: before the flat field, the part of the backdrop that
    the grow lamp does not reach looks green beside the part it does (the photo is balanced on
    their mix); that is light, not plant. Such light is a solid band; a plant as large (a
    leafy tree late in an episode) is branches with backdrop between them, and must stay out
    of the light's estimate, or it is divided away."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(rough.view(np.uint8),
                                                               connectivity=8)
    area = stats[:, cv2.CC_STAT_AREA]
    box = stats[:, cv2.CC_STAT_WIDTH] * stats[:, cv2.CC_STAT_HEIGHT]
    flood = (area > FLOOD_FRACTION * rough.size) & (area > FLOOD_FILL * box)
    flood[0] = False
    return rough & ~flood[labels] if flood.any() else rough


def _unlit_strips(new: np.ndarray) -> np.ndarray:
    """The pixels of ``new`` (in the mask, but not plant-coloured in the photo itself) in the
    columns that they fill for ``STRIP_FRACTION`` of the chamber's height or more.

    A strip of backdrop that a hard-edged lamp leaves unlit (between an LED bar's bands, or
    between the beam's edge and the wall) narrower than half the flat field's window keeps
    the lamp's colour in the light estimated there, so it reads as tissue after the division,
    from the floor to the top. A stem is plant-coloured in the photo for most of its height
    (the rough mask), so this leaves it alone.
    """
    columns = np.count_nonzero(new, axis=0) >= STRIP_FRACTION * new.shape[0]
    return new & columns[None, :]


def _floor_rows(index: np.ndarray, pixel_m: float) -> None:
    """The bottom rows of the grid border the soil, which is dark and brown too, and which
    blur and a fit off by a millimetre bring into them: there a pixel counts as tissue only
    as far as the pixel ``FLOOR_M`` above it does (a stem goes on down; the soil line has
    nothing above it). In place."""
    rows = index.shape[0]
    k = min(rows - 1, max(1, int(np.ceil(FLOOR_M / pixel_m))))
    np.minimum(index[rows - k:], index[rows - 2 * k:rows - k], out=index[rows - k:])


def _coverage(exg: np.ndarray, plant: np.ndarray, backdrop: float) -> np.ndarray:
    """Plant cover per pixel on and around the mask: ExG from the backdrop's level (0) to the
    greenest pixel within two pixels (1, the stem's own colour there)."""
    near = cv2.dilate(plant.astype(np.uint8), np.ones((3, 3), np.uint8))
    stem = cv2.dilate(exg, np.ones((5, 5), np.uint8)) - backdrop
    cover = cv2.divide(exg - backdrop, np.maximum(stem, 1e-3))
    np.clip(cover, 0.0, 1.0, out=cover)
    cover[near == 0] = 0.0
    return cover


def _hysteresis(exg: np.ndarray, low: float, high: float,
                seeds: np.ndarray | None = None, seed_level: float = 0.0) -> np.ndarray:
    """Pixels above ``low`` that join (4-connected) a pixel above ``high``, uint8 0/1: the
    hysteresis threshold of scikit-image's ``apply_hysteresis_threshold``, on OpenCV's
    connected components (several times faster on a chamber of mostly backdrop). With
    ``seeds``, the pixels above ``high`` must be above it and ``seed_level`` in ``seeds`` too."""
    count, labels = cv2.connectedComponents((exg > low).view(np.uint8), connectivity=4)
    strong = np.zeros(count, np.uint8)
    high_px = exg > high
    if seeds is not None:
        high_px &= seeds > max(high, seed_level)
    strong[labels[high_px]] = 1
    strong[0] = 0
    return strong[labels]


def _bridge(mask: np.ndarray, exg: np.ndarray, pale: float, min_px: float, ground_px: int,
            max_gap_px: int) -> None:
    """Join each piece of ``mask`` with no pixel in its bottom ``ground_px`` rows to one that
    may stand on the soil line, by a shortest way through at most ``max_gap_px`` pixels of
    ``exg`` above ``pale`` outside the mask (back by the greenest pixel of each step); a
    joined piece is a foothold for the next round. In place (uint8 0/1). A blurred internode
    can be paler than the threshold for a pixel or two (a real plant lost its top 15 cm so);
    a longer gap is left alone (a banded lamp's unlit line comes in pieces). A join that would
    connect two grounded pieces (two plants' business) is undone; specks are not joined.
    """
    count, pieces, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if count <= 2 or ground_px <= 0:
        return
    low = np.isin(np.arange(count), pieces[-ground_px:])
    big = stats[:, cv2.CC_STAT_AREA] >= min_px
    grounded, floating = low & big, ~low & big
    grounded[0] = floating[0] = False
    standing, stands = grounded[pieces], np.count_nonzero(grounded)  # never fewer pieces
    pale_gap = (exg > pale) & (mask == 0)
    far = max_gap_px + 2  # (a step count no bridge reaches)
    while floating.any() and grounded.any():
        # Steps from the grounded pieces (8-connected) through pale gap pixels and floating
        # pieces: a floating pixel at step s is s - 1 gap pixels away.
        steps = np.full(mask.shape, far, np.int16)
        reached = grounded[pieces]
        steps[reached] = 0
        open_ = pale_gap | floating[pieces]
        for step in range(1, far):
            grown = cv2.dilate(reached.view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
            grown &= open_ & ~reached
            steps[grown] = step
            reached |= grown
        touched = np.unique(pieces[(steps < far) & floating[pieces]])
        if touched.size == 0:
            return
        for q in touched:
            own = np.where(pieces == q, steps, far)
            row, col = np.unravel_index(np.argmin(own), own.shape)
            path = []
            for step in range(int(own[row, col]) - 1, 0, -1):  # back to the grounded piece
                r0, c0 = max(row - 1, 0), max(col - 1, 0)
                near = np.where(steps[r0:row + 2, c0:col + 2] == step,
                                exg[r0:row + 2, c0:col + 2], -np.inf)
                dr, dc = np.unravel_index(np.argmax(near), near.shape)
                row, col = r0 + dr, c0 + dc
                path.append((row, col))
            rows, cols = np.array(path, np.intp).reshape(-1, 2).T
            new = mask[rows, cols] == 0
            mask[rows[new], cols[new]] = 1
            labels = cv2.connectedComponents(mask, connectivity=8)[1]
            if np.unique(labels[standing]).size < stands:
                mask[rows[new], cols[new]] = 0  # it would join two grounded pieces
                floating[q] = False
                continue
            pale_gap[rows, cols] = False
            grounded[q], floating[q] = True, False
        floating[touched] = False


def _noise(index: np.ndarray, centre: float) -> float:
    """The backdrop's noise in an index whose backdrop level (median) is ``centre``: a
    robust standard deviation (the median absolute deviation's), on every third pixel."""
    return 1.4826 * float(np.median(np.abs(index[::3, ::3] - centre)))


def _plant_threshold(index: np.ndarray, floor: float, centre: float, noise: float) -> float:
    """Otsu's threshold of a greenness index, capped where it stands clearly out of the
    backdrop's ``noise``, and never below ``floor``.

    Otsu splits two classes; with two greens (a dark old stem under bright young shoots, or
    two plants) it splits the backdrop from the brighter one and loses the other.
    """
    return max(min(_otsu(index), centre + NOISE_SIGMAS * noise), floor)


def _otsu(exg: np.ndarray) -> float:
    """Otsu's threshold of an ExG image (OpenCV, on ExG scaled to 8 bits)."""
    scaled = np.clip((exg + 0.5) * EXG_SCALE, 0, 255).astype(np.uint8)
    level, _ = cv2.threshold(scaled, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    return float(level) / EXG_SCALE - 0.5
