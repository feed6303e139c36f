"""One photo -> the chamber's observation, plant state and reward, with how sure each is.

The pipeline is a short script of the pure steps (PlantCV's way): exposure -> markers -> plane
fit -> rectified photo -> plant mask -> trees of nodes -> measured ``ChamberState`` -> the
task's reward and the simulator's drawing of it. A step that cannot read the photo raises
``CameraError``; ``Pipeline.measure`` returns that as a measurement with ``ok`` False and no
numbers, so a caller never gets a reward the photo did not give.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import time

import cv2
import numpy as np

from growspace_camera.calibration import Calibrator, FitReport
from growspace_camera.errors import BAD_INPUT, CameraError, PLANTS, UNEXPLAINED
from growspace_camera.lens import Lens
from growspace_camera.markers import Detection, MarkerDetector, MarkerLayout, to_gray
from growspace_camera.measure import measured_state, Observer, score, Target
from growspace_camera.segment import (
    exposure, Exposure, Grid, plant_mask, rectify, SegmentParams, Segmentation)
from growspace_camera.nodes import measure_tree, PlantTree
from growspace_camera.skeleton import TreeParams
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import Light
from growspace_sim.core.state import ChamberState

MIN_PHOTO_PX = 16  # a smaller photo cannot hold four readable markers (camera_node's width)


@dataclass(frozen=True)
class PipelineParams:
    """Everything the pipeline accepts (camera_node's parameters of the same names)."""

    layout: MarkerLayout = MarkerLayout()
    segment: SegmentParams = SegmentParams()
    tree: TreeParams = TreeParams()
    max_fit_error_m: float = 0.005  # largest RMS marker-corner error of a fit or hold [m]
    # Largest fraction of the plant mask in pieces that hold no stem base. Such a piece is
    # plant the measured trees leave out (a leafy crown over a brown stem the mask missed:
    # its trees are stumps, and their reward a confident wrong number; 99 % of the issue's
    # small tree) or green that is not plant (a lamp's edge or cast). Half, not less: a blob
    # of lamp-cast green beside a plant measured whole leaves its reward right, and at 0.25
    # the twin's closed loop refused 26 such photos of 3,060 (control hard, 11 to 89 % of
    # the mask); on the twin's fidelity photos of grown plants it is 0 (docs/hardware.md).
    max_unexplained: float = 0.5
    lens: Lens | None = None  # the camera's calibration; None: a distortion-free lens
    # Most loops (holes) in the plant mask (``check_loops``). Plants seen from the side cross
    # themselves a few times: the twin's development photos (576, steps 6-50, tuning
    # combinations and the old twin) at most 9, a real small tree in leaf 12; a top view's
    # blades, overlapping round its centre, 46.
    max_loops: int = 20
    # Largest gap between touching plants' shares of the skeleton and their stems'
    # (``check_shares``). Twin development photos of two touching plants (fairness, oracle,
    # every step: 209 of 28 episodes): of the 8 beyond 0.25, 5 had a reward off by more than
    # 0.05; of the 201 within it, 14 (the twin draws each plant's stems 0.85-1.2 times as wide).
    max_share_gap: float = 0.25
    # How far over the measured plants' top a piece of plant that reaches no stem base may
    # lie (``check_floating``): farther, it is plant whose stem the mask missed. The twin's
    # development photos (2,304) have none; a real bolting plant's dark racemes, 0.26 m.
    max_float_m: float = 0.05


FLOAT_WIDTH_M = 0.01  # a piece this wide somewhere is plant, not an edge's line [m]


@dataclass
class Confidence:
    """How sure a measurement is: what was seen and what was dropped on the way.

    Attributes:
        markers_seen: Marker ids found in this photo.
        fit_held: The plane fit is an earlier photo's (some markers hidden here).
        fit_age: Photos since the fit was made.
        fit_error_m: RMS marker-corner error of the fit (or of the hold check) [m].
        exposure_mean: Mean grey level of the photo [0-1].
        saturated: Clipped fraction of the photo [0-1].
        threshold: ExG threshold of the mask.
        contrast: Mean ExG of plant minus backdrop.
        plant_pixels: Mask pixels of plant.
        specks: Mask pixels dropped as specks.
        skeleton_px: Skeleton pixels per plant.
        unattached_px: Skeleton pixels no stem base reaches.
        unexplained: Fraction of the plant mask in pieces that hold no stem base [0-1].
        loops: Holes in the plant mask (where branches or leaves cross in the photo).
        tips: Tips measured.
        tips_pruned: Skeleton end points dropped as spurs.
        leaves: Leaves cut off the shoots (their ends are not tips).
    """

    markers_seen: tuple[int, ...] = ()
    fit_held: bool = False
    fit_age: int = 0
    fit_error_m: float = float('nan')
    exposure_mean: float = float('nan')
    saturated: float = float('nan')
    threshold: float = float('nan')
    contrast: float = float('nan')
    plant_pixels: int = 0
    specks: int = 0
    skeleton_px: tuple[int, ...] = ()
    unattached_px: int = 0
    unexplained: float = float('nan')
    loops: int = 0
    tips: int = 0
    tips_pruned: int = 0
    leaves: int = 0


@dataclass
class Measurement:
    """What one photo gave. With ``ok`` False only ``error`` and ``confidence`` count.

    Attributes:
        ok: Every step read the photo.
        error: Why not (None when ok).
        observation: (res, res, 3) uint8 RGB, the simulator's channel convention.
        state: The measured ``ChamberState``.
        tree: The measured plants as node arrays (positions in m).
        reward, plant_rewards, success: The task's score of ``state``.
        confidence: See ``Confidence``.
        detections: The markers found (for the segmentation overlay).
        fit: The plane fit used, if any.
        grid: The rectified plane, if the photo got that far.
        segmentation: The plant mask, if the photo got that far.
        timings_ms: Milliseconds per step.
    """

    ok: bool
    error: CameraError | None = None
    observation: np.ndarray | None = field(default=None, repr=False)
    state: ChamberState | None = field(default=None, repr=False)
    tree: PlantTree | None = field(default=None, repr=False)
    reward: float = 0.0
    plant_rewards: np.ndarray = field(default_factory=lambda: np.zeros(0))
    success: bool = False
    confidence: Confidence = field(default_factory=Confidence)
    detections: list[Detection] = field(default_factory=list, repr=False)
    fit: FitReport | None = field(default=None, repr=False)
    grid: Grid | None = None
    segmentation: Segmentation | None = field(default=None, repr=False)
    timings_ms: dict[str, float] = field(default_factory=dict)


class Pipeline:
    """Measures photos; keeps the last good plane fit between them.

    Args:
        params: See ``PipelineParams``.
    """

    def __init__(self, params: PipelineParams = PipelineParams()) -> None:
        self.params = params
        self.detector = MarkerDetector(params.layout)
        self.calibrator = Calibrator(params.layout, params.max_fit_error_m, params.lens)
        self.observer = Observer()

    def measure(self, photo: np.ndarray, cfg: SimConfig, light: Light, target: Target,
                steps: int = 0) -> Measurement:
        """Measure one photo.

        Args:
            photo: (H, W, 3) uint8 BGR photo (as OpenCV captures and decodes); any other
                array (grey, BGRA, float, empty) or None is refused ``BAD_INPUT``.
            cfg: The chamber's configuration (challenge, sizes, node spacing).
            light: The light the gantry reached (drawn blue in the observation).
            target: The task's target of this episode (drawn red, scored against).
            steps: Steps taken in the episode (the state's ``steps``).

        Returns:
            The measurement; ``ok`` False with ``error`` when the photo could not be read.
        """
        out = Measurement(ok=False)
        clock = _Clock(out.timings_ms)
        try:
            self._measure(photo, cfg, light, target, steps, out, clock)
        except CameraError as e:
            out.ok, out.error = False, e
            out.reward, out.plant_rewards, out.success = 0.0, np.zeros(0), False
        out.timings_ms['total'] = sum(out.timings_ms.values())
        return out

    def _measure(self, photo: np.ndarray, cfg: SimConfig, light: Light, target: Target,
                 steps: int, out: Measurement, clock: _Clock) -> None:
        p, c = self.params, out.confidence
        check_photo(photo)
        if p.lens is not None:
            p.lens.check(photo.shape)
        gray = to_gray(photo)
        small = self.detector.shrink(gray)
        seen: Exposure = exposure(small, p.segment)
        c.exposure_mean, c.saturated = seen.mean, seen.saturated
        clock.lap('exposure')
        out.detections = self.detector.detect(gray, small)
        c.markers_seen = tuple(d.marker_id for d in out.detections)
        clock.lap('markers')
        out.fit = report = self.calibrator.update(out.detections)
        c.fit_held, c.fit_age, c.fit_error_m = report.held, report.age, report.check_error_m
        out.grid = grid = Grid(cfg.chamber_width, cfg.chamber_height, p.segment.pixel_m)
        rectified = rectify(photo, report.fit, grid)
        clock.lap('rectify')
        out.segmentation = seg = plant_mask(rectified, p.segment, p.tree.base_band_m)
        c.threshold, c.contrast, c.specks = seg.threshold, seg.contrast, seg.specks
        c.plant_pixels = int(np.count_nonzero(seg.mask))
        clock.lap('segment')
        out.tree = tree = measure_tree(seg.mask, grid, cfg.width_m(cfg.first_branch_height),
                                       cfg.branch_length_m, p.tree, seg.coverage)
        c.skeleton_px, c.unattached_px = tree.skeleton_px, tree.unattached_px
        c.tips, c.tips_pruned = int(tree.tips.size), tree.tips_pruned
        c.leaves = len(tree.leaf_tips)
        c.unexplained = tree.unexplained_px / max(c.plant_pixels, 1)
        c.loops = tree.loops
        clock.lap('skeleton')
        check_explained(tree, c.plant_pixels, p.max_unexplained)
        check_loops(tree, p.max_loops)
        check_floating(seg.mask, tree, grid, p.max_float_m)
        out.state = state = measured_state(tree, cfg, light, target, steps)
        check_shares(tree, p.max_share_gap)  # (once the plant count is the challenge's)
        reward, plant_rewards, success = score(state, cfg)
        out.reward, out.plant_rewards, out.success = float(reward), plant_rewards, bool(success)
        clock.lap('reward')
        out.observation = self.observer.image(state, cfg)
        clock.lap('observation')
        out.ok = True


def check_explained(tree: PlantTree, plant_pixels: int, max_unexplained: float) -> None:
    """Raises CameraError ``UNEXPLAINED`` when more than ``max_unexplained`` of the plant mask
    lies in pieces that hold no stem base (the measured trees do not explain the photo)."""
    if tree.unexplained_px > max_unexplained * plant_pixels:
        share = tree.unexplained_px / max(plant_pixels, 1)
        raise CameraError(UNEXPLAINED, f'the plants measured from their stem bases explain '
                          f'{1 - share:.0%} of the plant mask: {tree.unexplained_px} of '
                          f'{plant_pixels} mask pixels reach no stem base (max_unexplained = '
                          f'{max_unexplained:g}); a stem the mask missed (brown, woody, '
                          f'hidden) or green that is not plant')


def check_floating(mask: np.ndarray, tree: PlantTree, grid: Grid, max_float_m: float) -> None:
    """Raises CameraError ``UNEXPLAINED`` when, over a measured plant and more than
    ``max_float_m`` above its top, a piece of plant that holds no measured node is at least
    ``FLOAT_WIDTH_M`` wide somewhere (a leaf, a flower cluster; not the thin line a cabinet
    edge or a lamp's beam edge leaves): plant whose stem the mask missed (dark, thin or woody),
    so the measured trees are its lower part and a reward read from them a confident wrong
    number."""
    if not tree.unexplained_px or max_float_m <= 0:
        return
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.view(np.uint8),
                                                               connectivity=8)
    # The pieces holding measured nodes (a node may sit a pixel off its skeleton's mask).
    at_nodes = np.zeros(mask.shape, np.uint8)
    rows = (grid.shape[0] - tree.nodes[:, 1] / grid.pixel_m).astype(int)
    cols = (tree.nodes[:, 0] / grid.pixel_m).astype(int)
    at_nodes[np.clip(rows, 0, grid.shape[0] - 1), np.clip(cols, 0, grid.shape[1] - 1)] = 1
    measured = np.zeros(count, bool)
    measured[labels[cv2.dilate(at_nodes, np.ones((3, 3), np.uint8)) > 0]] = True
    measured[0] = False
    # Wide somewhere: what is left of it after an opening by a disc about FLOAT_WIDTH_M across
    # (an odd number of pixels: a disc centred on its pixel).
    across = 2 * int(round(0.5 * FLOAT_WIDTH_M / grid.pixel_m)) + 1
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (across, across))
    wide = np.zeros(count, bool)
    wide[labels[cv2.morphologyEx(mask.view(np.uint8), cv2.MORPH_OPEN, disc,
                                 borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0]] = True
    wide[0] = False  # (the backdrop)
    left, top, width, height = stats[:, :4].T  # per piece, its bounding box [px]
    reach = max_float_m / grid.pixel_m
    gaps = []  # rows between a floating piece and the top of the plants it lies over
    for piece in np.flatnonzero(wide & ~measured):
        under = measured & (left - reach < left[piece] + width[piece]) & \
            (left + width + reach > left[piece])
        if under.any() and (above := top[under].min() - (top[piece] + height[piece])) > reach:
            gaps.append(above)
    if gaps:
        gap = min(gaps) * grid.pixel_m  # the nearest such piece
        raise CameraError(UNEXPLAINED, f'plant {gap:.2f} m above the measured plants reaches '
                          f'no stem base (max_float_m = {max_float_m:g}): a stem the mask '
                          f'missed below it (dark, thin or woody), or green that is not plant')


def check_loops(tree: PlantTree, max_loops: int) -> None:
    """Raises CameraError ``UNEXPLAINED`` when the plant mask is a net of more than
    ``max_loops`` loops: each loop is a crossing whose branches the skeleton must guess, and
    so many are no plant seen from the side (a top view, a tangle, a dense mat of leaves)."""
    if tree.loops > max_loops:
        raise CameraError(UNEXPLAINED, f'the plant mask is a net of {tree.loops} loops '
                          f'(max_loops = {max_loops}): not a plant seen from the side, whose '
                          f'branches cross a few times (a top view, a tangle or a mat of leaves)')


def check_shares(tree: PlantTree, max_gap: float) -> None:
    """Raises CameraError ``PLANTS`` when the plants' shares of the skeleton contradict their
    stems: a stem thickens with what it carries (the simulator's segments as the cube root of
    their descendants; real stems by the pipe model), so each plant's share of the skeleton
    should be near its stem's radius cubed over all of theirs. Where two plants touch (a
    branch or a leaf lying on the other plant's stem), the skeleton's shortest paths can hand
    one plant's crown to the other: its reward is then a confident wrong number. Plants that
    do not touch (in pieces of the mask of their own) cannot be shared out wrongly, and are
    not compared: stems differ by more than what they carry (the cube turns a stem 20 %
    wider into a share 1.7 times as large)."""
    for piece in set(tree.piece):
        together = [p for p in range(tree.plants) if tree.piece[p] == piece]
        if len(together) > 1:
            _check_shares(np.asarray(tree.stem_radius_m, float)[together],
                          np.asarray(tree.skeleton_px, float)[together], max_gap)


def _check_shares(radius: np.ndarray, length: np.ndarray, max_gap: float) -> None:
    if np.isnan(radius).any() or length.sum() == 0:
        return
    stems = radius ** 3 / np.sum(radius ** 3)
    shares = length / length.sum()
    if np.abs(shares - stems).max() > max_gap:
        def listed(values: np.ndarray) -> str:
            return ', '.join(f'{v:.2f}' for v in values)
        raise CameraError(PLANTS, f'the plants measured do not match their stems: their '
                          f'shares of the skeleton are {listed(shares)}, their stems (radii '
                          f'{", ".join(f"{1000 * r:.1f}" for r in radius)} mm, cubed) say '
                          f'{listed(stems)}, more than max_share_gap = {max_gap:g} apart; '
                          f'plants that touch '
                          f"(a branch or a leaf on the other plant's stem) shared out wrongly")


def check_photo(photo: object) -> None:
    """Raises CameraError ``BAD_INPUT`` naming what it got unless ``photo`` is an 8-bit BGR
    photo: a (H, W, 3) uint8 array with both sides at least ``MIN_PHOTO_PX``.

    OpenCV's own errors for such arrays (``cv2.error`` from a colour conversion, a grey array
    read as a photo's plane) say nothing about where the array came from.
    """
    if not isinstance(photo, np.ndarray):
        raise CameraError(BAD_INPUT, f'the photo must be an (H, W, 3) uint8 BGR array, got '
                          f'{type(photo).__name__}')
    got = f'a {photo.dtype} array of shape {photo.shape}'
    if photo.dtype != np.uint8:
        raise CameraError(BAD_INPUT, f'the photo must be 8-bit (uint8) BGR, got {got}'
                          + (' (scale a float photo to 0-255 and convert with '
                             'astype(np.uint8))' if photo.dtype.kind == 'f' else ''))
    if photo.ndim == 2 or (photo.ndim == 3 and photo.shape[2] == 1):
        raise CameraError(BAD_INPUT, f'the photo must be BGR (H, W, 3), got {got}: a grey '
                          f'photo (cv2.cvtColor(photo, cv2.COLOR_GRAY2BGR) if it is one)')
    if photo.ndim == 3 and photo.shape[2] == 4:
        raise CameraError(BAD_INPUT, f'the photo must be BGR (H, W, 3), got {got}: BGRA '
                          f'(drop the alpha: cv2.cvtColor(photo, cv2.COLOR_BGRA2BGR))')
    if photo.ndim != 3 or photo.shape[2] != 3:
        raise CameraError(BAD_INPUT, f'the photo must be BGR (H, W, 3), got {got}')
    if min(photo.shape[:2]) < MIN_PHOTO_PX:
        raise CameraError(BAD_INPUT, f'the photo must be at least {MIN_PHOTO_PX} x '
                          f'{MIN_PHOTO_PX} px, got {got}')


def overlay(photo: np.ndarray, measurement: Measurement, scale: float = 0.5) -> np.ndarray:
    """The segmentation picture for people: the mask in green, markers outlined, tips red and
    the ends of the leaves cut off the shoots yellow.

    Args:
        photo: The measured photo (BGR).
        measurement: Its measurement.
        scale: Size of the picture relative to the photo.

    Returns:
        (h, w, 3) uint8 BGR.
    """
    picture = cv2.resize(photo, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    fit, grid, seg = measurement.fit, measurement.grid, measurement.segmentation
    if fit is not None and grid is not None and seg is not None:
        rows, cols = np.nonzero(seg.mask)
        pixels = fit.fit.photo_points(grid.xz(rows, cols)) * scale
        inside = np.all((pixels >= 0) & (pixels < picture.shape[1::-1]), axis=1)
        r, c = pixels[inside, 1].astype(int), pixels[inside, 0].astype(int)
        picture[r, c] = (0.4 * picture[r, c] + (0, 153, 0)).astype(np.uint8)
        tree = measurement.tree
        if tree is not None:
            for points, colour in ((tree.nodes[tree.tips], (0, 0, 255)),
                                   (tree.leaf_tips, (0, 255, 255))):
                if len(points):
                    for x, y in fit.fit.photo_points(points) * scale:
                        cv2.circle(picture, (int(x), int(y)), 4, colour, 2)
    for d in measurement.detections:
        cv2.polylines(picture, [np.rint(d.corners * scale).astype(np.int32)], True,
                      (255, 0, 255), 2)
    if not measurement.ok and measurement.error is not None:
        cv2.putText(picture, str(measurement.error)[:90], (10, 30), cv2.FONT_HERSHEY_SIMPLEX,
                    0.7, (0, 0, 255), 2)
    return picture


class _Clock:
    def __init__(self, laps: dict[str, float]) -> None:
        self.laps = laps
        self.last = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.laps[name] = (now - self.last) * 1000.0
        self.last = now
