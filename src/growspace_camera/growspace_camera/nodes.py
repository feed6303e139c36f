"""Skeleton graph -> the simulator's node arrays: nodes at corners, junctions and tips.

The simulator grows straight segments of one length (the first stem ``first_branch_height``,
then ``branch_length``) from node to node; a branch leaves from a node, and a path can only
turn at one. So along each path from a stem base, a node is placed at every *key* pixel (a
corner where the path turns by ``corner_deg`` or more, a junction, an end point) that lies at
least half a segment beyond the previous node, and the run between two nodes is divided into
as many equal segments as its arc length holds. Arc length thus only has to be right between
two corners, not from the floor up; a tip is the end point carried on to the mask's edge by
the local radius.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math

import cv2
import numpy as np

from growspace_camera.segment import Grid
from growspace_camera.skeleton import skeleton_graph, SkeletonGraph, TreeParams

DIRECTION_PX = 10  # a tip's direction is taken over this many skeleton pixels
STRAIGHT_PX = 0.75  # RMS distance of a straight run's skeleton from its line [px]
CORNER_MIN = 0.8  # of a segment: a path turning nearer its last node is a rounded corner
TIP_BACK_PX = 4  # a tip's place across its shoot is the plant's cover from this far back
TIP_WIDTH_PX = 2  # a tip's radius is read from the cover across its shoot this far back
# A round end's radius is half the cover across the shoot less this (it narrows, and blur
# spreads a thin end's cover): the twin's tips are then unbiased, quartiles +-0.8 mm
TIP_NARROWING_PX = 0.7
LINE_REACH = 0.9  # of the spacing: a corner's lines are fitted within this of it (one segment)
REFINE_LIMIT = 0.25  # a corner node moves at most this far (of the spacing) to its lines' cross
STEM_BAND_M = (0.03, 0.08)  # a plant's stem radius is read this high up its first stem [m]


@dataclass
class PlantTree:
    """The measured plants, as the simulator's node arrays (roots first, one per plant).

    Attributes:
        nodes: (N, 2) float64 node positions (x, z) [m]; the first ``plants`` are the roots.
        parent: (N,) int32 parent node, -1 for a root; parent[i] < i.
        plant: (N,) int16 plant of each node.
        tips: (K,) int64 nodes that are measured tips (skeleton end points).
        plants: Stem bases found.
        tips_pruned: End points dropped as spurs.
        skeleton_px: Skeleton pixels per plant (its length in pixels, roughly).
        unattached_px: Skeleton pixels that no stem base reaches (loose bits of plant).
        unexplained_px: Mask pixels in pieces of the mask that hold no stem base.
        leaf_tips: (L, 2) float64 ends of the leaves cut off the shoots (x, z) [m]: not
            tips of the simulator's kind, so no reward counts them (``leaves``).
        stem_radius_m: Per plant, the radius of its stem ``STEM_BAND_M`` above the floor
            (the median over its skeleton there) [m]; NaN for a plant with no skeleton there.
        loops: Holes in the mask (backdrop it encloses): each is a loop in the skeleton,
            where branches or leaves cross in the photo, and a guess at which is which.
        piece: Per plant, the piece of the mask (8-connected) its stem base stands in:
            plants in one piece touch, and only they can be shared out wrongly.
    """

    nodes: np.ndarray
    parent: np.ndarray
    plant: np.ndarray
    tips: np.ndarray
    plants: int
    tips_pruned: int
    skeleton_px: tuple[int, ...]
    unattached_px: int
    unexplained_px: int = 0
    leaf_tips: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    stem_radius_m: tuple[float, ...] = ()
    loops: int = 0
    piece: tuple[int, ...] = ()


def measure_tree(mask: np.ndarray, grid: Grid, first_m: float, spacing_m: float,
                 params: TreeParams, coverage: np.ndarray | None = None) -> PlantTree:
    """The plants of a mask, as trees of nodes ``first_m`` then ``spacing_m`` apart.

    Args:
        mask: (rows, cols) bool plant mask on ``grid``.
        grid: The rectified plane.
        first_m: Arc length of the first node above a root [m] (the initial stem).
        spacing_m: Arc length between later nodes [m] (a segment).
        params: Base band, spur pruning, corners.
        coverage: Plant cover per pixel (``Segmentation.coverage``) for sub-pixel stem
            centres; None: the mask's own pixels.

    Raises:
        CameraError: ``NO_PLANT`` when the mask is empty or no skeleton reaches the floor.
    """
    g = skeleton_graph(mask, grid, params, coverage)
    builder = _Builder(g, mask, grid, first_m / grid.pixel_m, spacing_m / grid.pixel_m,
                       coverage)
    # Where a loop (branches crossing in the plane) was cut into a tree, the path ends
    # without an end point: it gets a node too, so the loop is drawn whole.
    leaf = np.zeros(g.pred.size, bool)
    leaf[g.order] = True
    leaf[g.pred[(g.pred >= 0) & ~g.removed]] = False
    leaf &= ~g.removed
    key = g.junction | _corners(g, grid.shape, np.radians(params.corner_deg)) | leaf
    builder.walk(key)
    builder.refine_corners(np.radians(params.corner_deg), REFINE_LIMIT * spacing_m)
    plant = np.array(builder.plant, np.int16)
    lengths = np.bincount(plant[np.array(builder.node_of, np.int64)[builder.kept]],
                          minlength=g.roots.size) if builder.kept else np.zeros(g.roots.size)
    # The mask's pieces and holes, on its bounding box (the chamber is mostly backdrop).
    left, top, width, height = cv2.boundingRect(mask.view(np.uint8))
    box = mask[top:top + height, left:left + width]
    unexplained, piece = _pieces(box, g.rows[g.roots] - top, g.cols[g.roots] - left)
    return PlantTree(np.array(builder.nodes, np.float64).reshape(-1, 2),
                     np.array(builder.parent, np.int32), plant,
                     np.array(builder.tips, np.int64), int(g.roots.size), g.pruned,
                     tuple(int(v) for v in lengths), g.unattached, unexplained,
                     g.xz[g.leaf_ends].reshape(-1, 2), _stem_radii(g, grid.pixel_m),
                     _loops(box), piece)


def _pieces(box: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> tuple[int, tuple[int, ...]]:
    """(mask pixels in pieces, 8-connected as the skeleton is, that hold none of the stem
    bases at (``rows``, ``cols``): plant the measured trees do not account for; the piece
    each base stands in), of a mask cropped to its bounding box."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(box.astype(np.uint8),
                                                               connectivity=8)
    piece = labels[rows, cols]
    rooted = np.zeros(count, bool)
    rooted[piece] = True
    rooted[0] = True  # the background
    return int(stats[~rooted, cv2.CC_STAT_AREA].sum()), tuple(int(v) for v in piece)


def _loops(box: np.ndarray) -> int:
    """Holes in a mask cropped to its bounding box: pieces of its backdrop (4-connected, as
    the 8-connected skeleton goes round them) that do not reach the box's edge."""
    if min(box.shape) < 3:
        return 0
    count, labels = cv2.connectedComponents((~box).view(np.uint8), connectivity=4)
    edge = np.unique(np.concatenate((labels[0], labels[-1], labels[:, 0], labels[:, -1])))
    return count - 1 - int(np.count_nonzero(edge))  # label 0 is the plant


def _stem_radii(g: SkeletonGraph, pixel_m: float) -> tuple[float, ...]:
    """Each plant's stem radius ``STEM_BAND_M`` above the floor [m] (NaN: no skeleton there)."""
    low, high = (h / pixel_m for h in STEM_BAND_M)
    band = (g.arc > low) & (g.arc < high) & ~g.removed
    return tuple(float(np.median(g.radius[band & (g.owner == p)])) * pixel_m
                 if np.any(band & (g.owner == p)) else float('nan') for p in range(g.roots.size))


def _corners(g: SkeletonGraph, shape: tuple[int, int], min_rad: float) -> np.ndarray:
    """Pixels where a path turns by ``min_rad`` or more, the sharpest in their 5 x 5 area."""
    image = np.zeros(shape, np.float32)
    image[g.rows, g.cols] = g.turning
    turning = image[g.rows, g.cols]  # compared in float32, as the dilated peaks are
    peak = cv2.dilate(image, np.ones((5, 5), np.uint8))[g.rows, g.cols]
    return (turning >= min_rad) & (turning >= peak) & ~g.removed


@dataclass
class _Run:
    """The skeleton between two key nodes: no corner inside, so one straight line."""

    start: int  # the node it leaves
    end: int  # the key node it reaches
    inner: list[int]  # nodes placed evenly between them
    pixels: np.ndarray  # (k, 2) its skeleton pixels (x, z) [m]
    fractions: np.ndarray  # where along it start..end its nodes are (the last is 1)
    end_radius: float  # the mask radius at its end [m]
    was: tuple[np.ndarray, np.ndarray] = ()  # its ends before the corners were refined


Line = tuple[np.ndarray, np.ndarray]  # (a point, a unit direction)


def _lines(run: _Run, nodes: list, radius_at, pixel_m: float,  # noqa: ANN001
           reach_m: float) -> tuple[Line | None, Line | None]:
    """A run's lines (``_fit``) next to its end and its start: fitted to its pixels within
    ``reach_m`` of that end, away from both ends (the stems they meet bend its skeleton). A
    run through nodes placed between (a gentle bend) is straight one segment at a time."""
    a, b = np.array(nodes[run.start]), np.array(nodes[run.end])
    points = run.pixels
    if len(points) < 5:
        return None, None
    from_a, from_b = np.hypot(*(points - a).T), np.hypot(*(points - b).T)
    away = (from_a > radius_at(run.start) + 0.004) & (from_b > run.end_radius + 0.004)
    at_end, at_start = away & (from_b < reach_m), away & (from_a < reach_m)
    end_line = _fit(points[at_end], b - a, pixel_m)
    if np.array_equal(at_end, at_start):  # (a run no longer than the reach: one segment)
        return end_line, end_line
    return end_line, _fit(points[at_start], b - a, pixel_m)


def _fit(points: np.ndarray, towards: np.ndarray, pixel_m: float) -> Line | None:
    """(point, unit direction ``towards`` a way) of the line through ``points``; None for
    fewer than 5 or points not straight (further than ``STRAIGHT_PX`` from it, RMS)."""
    if len(points) < 5:
        return None
    centre = points.mean(axis=0)
    # The principal axis of the points, from their 2 x 2 scatter (an SVD's, in closed form).
    (sxx, sxz), (_, szz) = (points - centre).T @ (points - centre)
    half_gap = float(np.hypot(0.5 * (sxx - szz), sxz))
    across = max(0.5 * (sxx + szz) - half_gap, 0.0)  # the scatter across the line
    if across > (STRAIGHT_PX * pixel_m) ** 2 * len(points):
        return None  # the run bends (at a node the walk did not see as a corner): no line
    angle = 0.5 * np.arctan2(2.0 * sxz, sxx - szz)
    direction = np.array([np.cos(angle), np.sin(angle)])
    return centre, direction if np.dot(direction, towards) >= 0 else -direction


def _angle(u: np.ndarray, v: np.ndarray) -> float:
    return math.acos(min(1.0, max(-1.0, float(u[0] * v[0] + u[1] * v[1]))))


def _intersect(first: tuple[np.ndarray, np.ndarray],
               second: tuple[np.ndarray, np.ndarray]) -> np.ndarray | None:
    """Where two lines (point, unit direction) cross; None for (near) parallel ones."""
    (p, u), (q, v) = first, second
    cross = float(v[0] * u[1] - u[0] * v[1])  # det [u, -v]
    if abs(cross) < 1e-6:
        return None
    t = float((q[1] - p[1]) * v[0] - (q[0] - p[0]) * v[1]) / cross  # Cramer's rule
    return p + t * u


class _Builder:
    """Walks the paths in order, placing nodes (see the module docstring)."""

    def __init__(self, g: SkeletonGraph, mask: np.ndarray, grid: Grid, first_px: float,
                 spacing_px: float, coverage: np.ndarray | None = None) -> None:
        self.g, self.mask, self.grid, self.pixel_m = g, mask, grid, grid.pixel_m
        self.cover = coverage
        self.pred = g.pred.tolist()  # (walked pixel by pixel: a list's items are cheaper)
        self.first, self.spacing = first_px, spacing_px
        plants = g.roots.size
        self.nodes = [(float(x), 0.0) for x in g.root_x]  # each root on the floor
        self.parent, self.plant = [-1] * plants, list(range(plants))
        self.node_pixel = g.roots.tolist()
        self.tips: list[int] = []
        n = g.pred.size
        self.node_of, self.since = [-1] * n, [0.0] * n
        self.kept: list[int] = []
        self.runs: list[_Run] = []

    def refine_corners(self, min_rad: float, limit_m: float) -> None:
        """Move each corner node to where the straight lines of its two runs meet.

        A thick stem's skeleton rounds its corners off (towards the inside, by up to its
        radius); a segment each way (``LINE_REACH``) they are straight: their lines cross at it.
        Nodes between two corners are then spaced evenly on the line again.
        """
        into = {run.end: run for run in self.runs}
        out: dict[int, list[_Run]] = {}
        for run in self.runs:
            out.setdefault(run.start, []).append(run)
        # The lines into and out of each node that may be a corner, fitted before any moves.
        corners = set(into) - set(self.tips)
        reach = LINE_REACH * self.spacing * self.pixel_m
        lines, leaving_lines = {}, {}
        for run in self.runs:
            if run.end in corners or run.start in corners:
                lines[id(run)], leaving_lines[id(run)] = _lines(
                    run, self.nodes, self.radius_at, self.pixel_m, reach)
        for run in self.runs:
            run.was = (np.array(self.nodes[run.start]), np.array(self.nodes[run.end]))
        placed = self._first_nodes(limit_m)
        for node, arriving in into.items():
            if node not in corners or node in placed or arriving.start < 0 \
                    or lines[id(arriving)] is None:
                continue
            best = None
            for leaving in out.get(node, ()):
                line = leaving_lines[id(leaving)]
                if line is None:
                    continue
                angle = _angle(lines[id(arriving)][1], line[1])
                if angle >= min_rad and (best is None or angle > best[0]):
                    best = (angle, line)
            if best is None:
                continue
            corner = _intersect(lines[id(arriving)], best[1])
            # A rounded corner is off by about the stem's radius, and the node is on the stem:
            # a crossing farther out comes from a run that is not straight after all.
            reach = min(limit_m, 2.0 * self.radius_at(node) + 2.0 * self.pixel_m)
            if corner is not None and np.hypot(*(corner - self.nodes[node])) < reach \
                    and self._on_plant(corner):
                self.nodes[node] = (float(corner[0]), float(corner[1]))
        for run in self.runs:  # nodes between two ends follow them, the nearer one more
            moved_a = np.array(self.nodes[run.start]) - run.was[0]
            moved_b = np.array(self.nodes[run.end]) - run.was[1]
            for k, t in zip(run.inner, run.fractions[:-1]):
                self.nodes[k] = tuple(np.array(self.nodes[k]) + (1 - t) * moved_a
                                      + t * moved_b)

    def _first_nodes(self, limit_m: float) -> set[int]:
        """Put the first node of each stem one first segment up its fitted line.

        Where the first stem ends in a junction or a corner, the skeleton's fork sits off the
        node by up to the stem's radius (thick there: the whole plant is above it), and the
        first segment's length is known (``first_branch_height``). Its line, fitted away
        from both ends, gives the direction. Returns the nodes so placed.
        """
        placed = set()
        for run in self.runs:
            if self.parent[run.start] >= 0 or run.inner or run.end in self.tips:
                continue
            line = _lines(run, self.nodes, self.radius_at, self.pixel_m, math.inf)[1]
            if line is None:
                continue
            root = np.array(self.nodes[run.start])
            node = root + self.first * self.pixel_m * line[1]
            if np.hypot(*(node - self.nodes[run.end])) < limit_m:
                self.nodes[run.end] = (float(node[0]), float(node[1]))
                placed.add(run.end)
        return placed

    def _on_plant(self, xz: np.ndarray) -> bool:
        """Whether a point (x, z) [m] lies on the mask."""
        rows, cols = self.mask.shape
        row = int(np.floor(rows - xz[1] / self.pixel_m))
        col = int(np.floor(xz[0] / self.pixel_m))
        return 0 <= row < rows and 0 <= col < cols and bool(self.mask[row, col])

    def radius_at(self, node: int) -> float:
        """The mask radius at a node's skeleton pixel [m] (0 for a placed-between node)."""
        pixel = self.node_pixel[node]
        return float(self.g.radius[pixel]) * self.pixel_m if pixel >= 0 else 0.0

    def walk(self, key: np.ndarray) -> None:
        """Place the nodes at the ``key`` pixels, path by path."""
        g = self.g
        pred, arc, removed = self.pred, g.arc.tolist(), g.removed.tolist()
        end = np.zeros(len(pred), bool)
        end[g.ends] = True
        key, end = key.tolist(), end.tolist()
        for k, r in enumerate(g.roots.tolist()):
            self.node_of[r], self.since[r] = k, arc[r]  # a base's height above the floor
        for p in g.order.tolist():
            q = pred[p]
            if q < 0:
                continue
            self.node_of[p] = self.node_of[q]
            self.since[p] = self.since[q] + arc[p] - arc[q]
            if removed[p]:
                continue
            self.kept.append(p)
            if key[p]:
                self._key(p, end[p])

    def _key(self, p: int, is_end: bool) -> None:
        """Nodes up to key pixel ``p`` (a tip node at an end point)."""
        g, last = self.g, self.node_of[p]
        from_root = self.parent[last] < 0
        reach = self.since[p]
        position = g.xz[p]
        if is_end:  # the tip is where the mask ends, beyond the skeleton's end
            position = self._tip(p)
            reach += float(np.hypot(*(position - g.xz[p]))) / self.pixel_m
        expected = self.first if from_root else self.spacing
        if not is_end and reach < CORNER_MIN * expected:
            return  # the same node seen again (a junction's cluster, a corner's shoulder)
        if from_root:
            count = 1 + max(0, round((reach - self.first) / self.spacing))
            arcs = self.first + self.spacing * np.arange(count)
            arcs *= reach / arcs[-1]
        else:
            count = max(1, round(reach / self.spacing))
            arcs = reach * np.arange(1, count + 1) / count
        path_s, path_xz = self._path(p, last, reach, position)
        start, inner = last, []
        for s in arcs[:-1]:
            last = self._add(np.interp(s, path_s, path_xz[:, 0]),
                             np.interp(s, path_s, path_xz[:, 1]), last)
            inner.append(last)
        node = self._add(float(position[0]), float(position[1]), last)
        self.node_pixel[node] = p
        self.runs.append(_Run(start, node, inner, path_xz[1:-1], arcs / reach,
                              float(g.radius[p]) * self.pixel_m))
        if is_end:
            self.tips.append(node)
        self.node_of[p], self.since[p] = node, 0.0

    def _path(self, p: int, last: int, reach: float,
              end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arc positions and (x, z) of the path from node ``last`` to pixel ``p`` (ending at
        ``end``, the key pixel or the tip beyond it)."""
        g, stop, pred = self.g, self.node_pixel[last], self.pred
        pixels = []
        while p != stop and p >= 0:
            pixels.append(p)
            p = pred[p]
        pixels.reverse()
        s = [0.0] + [self.since[k] for k in pixels] + [reach]
        xz = np.vstack((self.nodes[last], g.xz[pixels].reshape(-1, 2), end))
        return np.maximum.accumulate(np.array(s)), xz

    def _add(self, x: float, z: float, parent: int) -> int:
        self.nodes.append((float(x), float(z)))
        self.parent.append(parent)
        self.plant.append(self.plant[parent])
        self.node_pixel.append(-1)
        return len(self.nodes) - 1

    def _tip(self, end: int) -> np.ndarray:
        """The tip beyond a skeleton end point (x, z) [m]: the mask's edge farthest along the
        branch's direction, within a few radii of the end (thinning leaves the skeleton's
        end short of the tip, and often hooked to one side), less the end's radius."""
        g, p = self.g, end
        for _ in range(DIRECTION_PX):
            if self.pred[p] < 0:
                break
            p = self.pred[p]
        d = g.xz[end] - g.xz[p]
        norm = float(np.hypot(*d))
        if norm == 0:
            return g.xz[end]
        d /= norm
        reach = int(np.ceil(g.radius[end])) + 3  # px
        r, c = int(g.rows[end]), int(g.cols[end])
        top, left = max(0, r - reach), max(0, c - reach)
        rows, cols = np.nonzero(self.mask[top:r + reach + 1, left:c + reach + 1])
        offset = self.grid.xz(rows + top, cols + left) - g.xz[end]
        along = offset @ d
        # Only the branch's own pixels: those near its axis (not a neighbour's, beside it).
        beside = np.abs(offset[:, 0] * d[1] - offset[:, 1] * d[0])
        # A mask end farther than a radius or so beyond the skeleton's touches something else.
        mine = (beside <= (g.radius[end] + 1.5) * self.pixel_m) \
            & (along <= (g.radius[end] + 2.0) * self.pixel_m)
        if not np.any(mine & (along > 0)):
            return g.xz[end]
        along = np.where(mine, along, -np.inf)
        at_apex = along >= along.max() - 0.5 * self.pixel_m
        apex = offset[at_apex].mean(axis=0)
        if self.cover is None:
            # A round tip's node is its end's radius inside the mask's edge (apex pixels' centres
            # lie half a pixel inside it; the distance transform counts half a pixel beyond).
            back = max(0.0, float(g.radius[end]) - 1.0) * self.pixel_m
            return g.xz[end] + apex - back * d
        # With the cover, to a fraction of a pixel: the edge lies as far into the apex pixels
        # as the plant covers them, less the end's radius (half the cover across the shoot
        # behind it, less TIP_NARROWING_PX); across it, the cover's centroid over its end.
        cover = self.cover[top:r + reach + 1, left:c + reach + 1][rows, cols] * mine
        px = self.pixel_m
        behind = cover[(along < 0) & (along >= -TIP_WIDTH_PX * px)].sum() / (2 * TIP_WIDTH_PX)
        edge = float(apex @ d) + (float(cover[at_apex].mean()) - 0.5) * px
        tip_along = edge - max(0.0, float(behind) - TIP_NARROWING_PX) * px
        near_end = cover * (along >= -TIP_BACK_PX * px)
        side = np.array([-d[1], d[0]])
        total = float(near_end.sum())
        tip_side = float(near_end @ (offset @ side)) / total if total > 0 else float(apex @ side)
        return g.xz[end] + tip_along * d + tip_side * side
