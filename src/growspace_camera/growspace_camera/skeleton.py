"""Plant mask -> skeleton graph: paths from each stem base, arc lengths, corners, tips.

The mask's skeleton (``skimage.morphology.skeletonize``) is a pixel graph of 8-neighbours.
Each group of skeleton pixels near the floor may be a stem base (sorted left to right: plant 0
is the leftmost, as in the simulator's layouts); Dijkstra from all bases at once gives each
pixel its base and the path back to it, so crossing branches (loops in 2-D) still form trees.
Its cost grows as tissue thins (the way down from a tip runs through ever thicker stems): a
loop is cut where a leaf or a thin shoot lies across a branch of its own plant or the next.
A group is a base only if it rises near vertical and, so grown, has a tip of its own: a leaf
drooping across the soil line has neither, and is a leaf of the plant it hangs from. Arc
length is summed over chords of a few pixels (8-steps make a line at 22.5 degrees 8 % too
long). Short end branches that thinning leaves on thick stems (spurs) are pruned, and so are
the ends it leaves in the corners of a stem's square cut end; the rest are the tips.
``growspace_camera.nodes`` turns the graph into the simulator's node arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from skimage.morphology import skeletonize

from growspace_camera.errors import CameraError, NO_PLANT
from growspace_camera.leaves import cut_leaves
from growspace_camera.segment import Grid

NEIGHBOURS = ((0, 1, 1.0), (1, -1, np.sqrt(2.0)), (1, 0, 1.0), (1, 1, np.sqrt(2.0)))
CHORD_PX = 5  # arc length is summed over chords this many steps long
TURN_PX = 8  # turning is measured between chords this long (a thick stem rounds its corners)
THIN_PX = 5.0  # a path costs (1 + (THIN_PX / radius) ** 2) per pixel (tuning: 4-6 alike)


@dataclass(frozen=True)
class TreeParams:
    """What the skeleton step accepts (ROS parameters of camera_node, same names).

    Attributes:
        base_band_m: Skeleton within this height of the floor is a stem base [m].
        spur_m: End branches shorter than this are spurs [m] ...
        spur_radii: ... or shorter than this many stem radii at their junction ...
        spur_taper: ... unless their end is thinner than this fraction of that radius: a shoot
            narrows to its tip, while a thinning spur ends inside the thick stem it leaves.
        corner_deg: A path turning by at least this much has a node there [deg].
        min_stem_m: A base carrying less skeleton than this is a speck, not a plant [m].
        max_base_tilt_deg: A piece of plant reaching the floor is a stem base only if its
            ``min_stem_m`` above the base band rise within this angle of vertical [deg] (a
            first stem is vertical; a leaf or branch lying across the soil line is slanted).
        leaf_widening: An end branch that widens to this many times its narrowest radius
            ends in a leaf, cut off its shoot (``leaves``); 0: no leaves are cut.
        petiole_m: A shoot left shorter than this by cutting its leaf off is a petiole: all
            leaf [m].
        leaf_end_m: An end branch this wide near its end is a leaf blade: a shoot's end is
            thinner [m]; 0: off.
    """

    base_band_m: float = 0.03
    spur_m: float = 0.015
    spur_radii: float = 2.0
    spur_taper: float = 0.5
    corner_deg: float = 15.0
    min_stem_m: float = 0.05
    max_base_tilt_deg: float = 35.0
    leaf_widening: float = 1.5
    petiole_m: float = 0.025
    leaf_end_m: float = 0.019


@dataclass
class SkeletonGraph:
    """The skeleton as paths from the stem bases (pixels are indexed 0..n-1).

    Attributes:
        rows, cols: (n,) grid pixel of each skeleton pixel.
        xz: (n, 2) chamber position of each skeleton pixel [m].
        order: Reached pixels in path order (every pixel after its predecessor).
        pred: (n,) predecessor on the path to the base; -1 for a base or an unreached pixel.
        arc: (n,) arc length from the floor [px].
        radius: (n,) distance to the mask's edge [px].
        turning: (n,) sharpest turn a path makes at the pixel [rad].
        junction: (n,) bool, three or more branches meet (after spur pruning).
        removed: (n,) bool, pixel of a pruned spur.
        ends: Kept end points (the tips), in path order.
        leaf_ends: End points of the leaves cut off (``leaves``).
        roots: (P,) the base pixel of each plant, left to right.
        root_x: (P,) each stem's x on the floor [m].
        pruned: Spurs pruned.
        unattached: Skeleton pixels no base reaches.
        owner: (n,) the base (an index into ``roots``) each pixel's path leads to; -1: none.
    """

    rows: np.ndarray
    cols: np.ndarray
    xz: np.ndarray
    order: np.ndarray
    pred: np.ndarray
    arc: np.ndarray
    radius: np.ndarray
    turning: np.ndarray
    junction: np.ndarray
    removed: np.ndarray
    ends: list[int]
    leaf_ends: list[int]
    roots: np.ndarray
    root_x: np.ndarray
    pruned: int
    unattached: int
    owner: np.ndarray


def skeleton_graph(mask: np.ndarray, grid: Grid, params: TreeParams,
                   coverage: np.ndarray | None = None) -> SkeletonGraph:
    """The skeleton of a plant mask as paths from its stem bases.

    Args:
        mask: (rows, cols) bool plant mask on ``grid``.
        grid: The rectified plane.
        params: Base band, spur pruning.
        coverage: (rows, cols) plant cover per pixel in [0, 1] (``Segmentation.coverage``):
            skeleton pixels and stem bases are placed at its centroids, to a fraction of a
            pixel; None: at the mask's.

    Raises:
        CameraError: ``NO_PLANT`` when the mask is empty or no skeleton reaches the floor.
    """
    # Thinning and distances on the plant's bounding box (with a margin) only: the chamber is
    # mostly backdrop.
    left, top, width, height_px = cv2.boundingRect(mask.astype(np.uint8))
    top, left = max(0, top - 2), max(0, left - 2)
    box = (slice(top, top + height_px + 4), slice(left, left + width + 4))
    rows, cols = np.nonzero(skeletonize(mask[box]))
    radius = cv2.distanceTransform(mask[box].astype(np.uint8), cv2.DIST_L2, 3)[rows, cols]
    cover = (mask if coverage is None else coverage)[box].astype(np.float64)
    centre_rows, centre_cols = _centres(cover, rows, cols, radius)
    rows, cols = rows + top, cols + left
    n = rows.size
    if n == 0:
        raise CameraError(NO_PLANT, 'no plant in the photo (the mask is empty)')
    height, band_px = grid.shape[0], params.base_band_m / grid.pixel_m
    # A thick stem's skeleton stops about its radius above the cut end at the floor.
    roots, root_cols, group = _roots(rows, cols, height, band_px + radius)
    if roots.size == 0:
        raise CameraError(NO_PLANT, f'no stem reaches the floor: {n} skeleton pixels, none '
                          f'within base_band_m = {params.base_band_m} m of z = 0')
    src, dst, weight = _edges(rows, cols, mask.shape)
    stem, tilt = _stem_bases(coo_matrix((weight, (src, dst)), shape=(n, n)).tocsr(), roots,
                             group, rows, cols, radius, height, band_px,
                             params.min_stem_m / grid.pixel_m, params)
    if not stem.any():
        tilts = ', '.join('too short' if np.isnan(t) else f'{t:.0f} deg' for t in tilt)
        raise CameraError(NO_PLANT, f'no stem reaches the floor: {roots.size} piece(s) of '
                          f'plant reach it, none a stem rising within max_base_tilt_deg = '
                          f'{params.max_base_tilt_deg:g} of vertical (tilts: {tilts})')
    roots, root_cols = roots[stem], root_cols[stem]
    root_cols = _stem_centres(mask, mask if coverage is None else coverage, root_cols,
                              band_px + radius[roots])
    degree = np.bincount(np.r_[src, dst], minlength=n)
    # (a stem pressed against the chamber's wall is as wide as it is there, not wider)
    walled = np.minimum(radius, np.minimum.reduce((rows + 1, cols + 1, height - rows,
                                                   mask.shape[1] - cols)))
    cost = weight * (1.0 + (THIN_PX / np.maximum(np.minimum(radius[src], radius[dst]),
                                                  0.5)) ** 2)
    while True:
        # A virtual source joins every base at its height: arc length counts from z = 0.
        graph = coo_matrix((np.r_[cost, height - 0.5 - rows[roots]],
                            (np.r_[src, np.full(roots.size, n)], np.r_[dst, roots])),
                           shape=(n + 1, n + 1))
        dist, pred = dijkstra(graph.tocsr(), directed=False, indices=n,
                              return_predecessors=True)
        pred = pred[:n].astype(np.int64)
        pred[pred == n] = -1
        reached = np.isfinite(dist[:n])
        order = np.argsort(dist[:n], kind='stable')[:int(reached.sum())]
        ancestor = _ancestors(pred, CHORD_PX)
        arc = _chord_lengths(order, dist[:n], ancestor, rows, cols)
        roots, root_cols, order, reached = _real_stems(roots, root_cols, order, pred, arc,
                                                      reached, params.min_stem_m / grid.pixel_m)
        if roots.size == 0:
            raise CameraError(NO_PLANT, f'no stem reaches the floor: {n} skeleton pixels, none '
                              f'of a stem at least min_stem_m = {params.min_stem_m} m tall')
        # The rest of each base's group in the band is the stem's cut end: no tips there.
        base = (group >= 0) & np.isin(group, group[roots])
        removed, ends, pruned = _prune(order, pred, arc, degree, radius, roots, base,
                                       max(params.spur_m / grid.pixel_m, 1.0), params)
        branching = degree >= 3
        branching[roots] = True
        ends, leaf_ends = cut_leaves(pred, arc, walled, branching, ends, removed,
                                     params.leaf_widening, params.petiole_m / grid.pixel_m,
                                     0.5 * params.leaf_end_m / grid.pixel_m)
        # Every plant grows up to a tip of its own. A leaf drooping from a stem onto the floor
        # meets it at its blade's end (no tip there), and the stem's base, over the thicker
        # and shorter way, reaches its petiole first: the leaf's contact has no tip.
        owner = _owners(order, pred, roots)
        barren = np.ones(roots.size, bool)
        barren[owner[ends + leaf_ends]] = False  # (a seedling may hold leaves alone)
        if not barren.any() or barren.all():
            break
        roots, root_cols = roots[~barren], root_cols[~barren]
    keep = ~removed[src] & ~removed[dst]
    junction = np.bincount(np.r_[src[keep], dst[keep]], minlength=n) >= 3
    return SkeletonGraph(
        rows=rows, cols=cols, xz=grid.xz(centre_rows + top, centre_cols + left), order=order,
        pred=pred, arc=arc,
        radius=radius, turning=_turning(_ancestors(pred, TURN_PX), rows, cols),
        junction=junction, removed=removed, ends=ends, leaf_ends=leaf_ends,
        roots=roots, root_x=(root_cols + 0.5) * grid.pixel_m, pruned=pruned,
        unattached=int(n - reached.sum()), owner=owner)


def _centres(cover: np.ndarray, rows: np.ndarray, cols: np.ndarray,
             radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each skeleton pixel moved to the centroid of the plant's cover in a square about it a
    pixel wider than the stem (float rows, columns).

    Thinning keeps one of the two middle columns of a stem an even number of pixels wide (half
    a pixel off its axis, always on the same side), and a mask's edges are whole pixels;
    across a straight stem its cover is symmetric about its axis, so the centroid lies on it.
    Summed-area tables (``cv2.integral``) give every pixel its own window at the same cost.
    """
    h, w = cover.shape
    area = cv2.integral(cover)
    moment_r = cv2.integral(cover * np.arange(h, dtype=np.float64)[:, None])
    moment_c = cv2.integral(cover * np.arange(w, dtype=np.float64))
    half = np.rint(radius).astype(np.int64) + 1
    r0, r1 = np.maximum(rows - half, 0), np.minimum(rows + half + 1, h)
    c0, c1 = np.maximum(cols - half, 0), np.minimum(cols + half + 1, w)

    def window(table: np.ndarray) -> np.ndarray:
        return table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0]

    count = window(area)
    empty = count < 1e-6  # (a cover of zero around a skeleton pixel: keep the pixel)
    count[empty] = 1.0
    return (np.where(empty, rows, window(moment_r) / count),
            np.where(empty, cols, window(moment_c) / count))


def _roots(rows: np.ndarray, cols: np.ndarray, height: int,
           band_px: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per group of touching skeleton pixels in the base band (per pixel: its height), its
    lowest pixel and its median column, left to right; and each skeleton pixel's group in
    that order (-1: above the band)."""
    group = np.full(rows.size, -1, np.int64)
    low = np.flatnonzero(rows >= height - band_px)
    if low.size == 0:
        return low, np.zeros(0), group
    top = int(rows[low].min())  # the band's first row
    image = np.zeros((height - top + 2, int(cols.max()) + 3), np.uint8)
    image[rows[low] - top + 1, cols[low] + 1] = 1
    count, labels = cv2.connectedComponents(image, connectivity=8)
    label = labels[rows[low] - top + 1, cols[low] + 1]
    members = [low[label == g] for g in range(1, count)]
    found = sorted(((m[np.argmax(rows[m])], float(np.median(cols[m])), m) for m in members),
                   key=lambda r: r[1])
    for k, (_, _, m) in enumerate(found):
        group[m] = k
    return (np.array([r[0] for r in found], np.int64), np.array([r[1] for r in found]),
            group)


def _stem_bases(graph, roots: np.ndarray, group: np.ndarray,  # noqa: ANN001 - sparse matrix
                rows: np.ndarray, cols: np.ndarray, radius: np.ndarray, height: int,
                band_px: float, rise_px: float,
                params: TreeParams) -> tuple[np.ndarray, np.ndarray]:
    """Which floor contacts rise as a stem does: near vertical (the simulator's first stem is
    vertical; a leaf drooping across the soil line, or a branch lying on it, meets it at a
    slant).

    Per contact, the shortest skeleton path from it up to ``rise_px`` (the least a stem
    carries, ``min_stem_m``) above the base band and its widest radius, taken where it is
    above those: whatever lies in the band (a thick stem's cut end, forked by thinning into
    its corners; a speck or a pot's rim touching it) stays out, and so do leaves joining the
    stem above (they are not on the shortest path up). The principal axis of that stretch
    gives the direction. Returns (rises as a stem, tilt from vertical [deg]; NaN when nothing
    reaches that high) per contact."""
    widest = np.zeros(roots.size)
    np.maximum.at(widest, group[group >= 0], radius[group >= 0])
    low = band_px + widest  # the stretch's bottom, per contact, above the floor [px]
    near, pred = dijkstra(graph, directed=False, indices=roots, return_predecessors=True,
                          limit=float(3.0 * (low.max() + rise_px)))
    near, pred = near.reshape(roots.size, -1), pred.reshape(roots.size, -1)
    above = height - 0.5 - rows  # each pixel's height above the floor [px]
    tilt = np.full(roots.size, np.nan)  # NaN: nothing reaches that high
    for k in range(roots.size):
        top = np.flatnonzero(np.isfinite(near[k]) & (above >= low[k] + rise_px))
        if top.size == 0:
            continue  # too short to be a stem (``_real_stems`` drops it as a speck)
        p, path = int(top[np.argmin(near[k][top])]), []
        while p >= 0:
            path.append(p)
            p = int(pred[k, p])
        path = np.array(path)
        path = path[above[path] >= low[k]]
        points = np.column_stack((rows[path], cols[path])).astype(float)
        _, _, axes = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)
        tilt[k] = np.degrees(np.arctan2(abs(axes[0][1]), abs(axes[0][0])))
    return np.nan_to_num(tilt, nan=90.0) <= params.max_base_tilt_deg, tilt


def _real_stems(roots: np.ndarray, root_cols: np.ndarray, order: np.ndarray, pred: np.ndarray,
                arc: np.ndarray, reached: np.ndarray,
                min_px: float) -> tuple[np.ndarray, ...]:
    """Drop bases whose skeleton reaches less than ``min_px`` of arc length (a speck of green
    on the soil line is not a plant: every plant has its first stem); their pixels become
    unattached."""
    base = _owners(order, pred, roots)
    height = np.zeros(roots.size)
    np.maximum.at(height, base[order], arc[order])
    keep = height >= min_px
    if keep.all():
        return roots, root_cols, order, reached
    order = order[keep[base[order]]]  # the kept bases stay in their left-to-right order
    reached = np.zeros_like(reached)
    reached[order] = True
    return roots[keep], root_cols[keep], order, reached


def _owners(order: np.ndarray, pred: np.ndarray, roots: np.ndarray) -> np.ndarray:
    """Each pixel's base (an index into ``roots``; -1 for a pixel no base reaches)."""
    base = np.full(pred.size, -1, np.int64)
    base[roots] = np.arange(roots.size)
    pred_list, base_list = pred.tolist(), base.tolist()
    for p in order.tolist():
        if base_list[p] < 0:
            base_list[p] = base_list[pred_list[p]]
    return np.array(base_list, np.int64)


def _stem_centres(mask: np.ndarray, cover: np.ndarray, columns: np.ndarray,
                  band_px: np.ndarray) -> np.ndarray:
    """Each stem's column: the median over the base band's rows of the centroid of the
    plant's cover across its mask run (the first background pixel each side included).

    The cover places a stem to a fraction of a pixel where its skeleton is only good to one
    (and hooks towards a corner of the stem's cut end)."""
    out = columns.astype(float).copy()
    height, width = mask.shape
    for k, (column, band) in enumerate(zip(columns.tolist(), band_px.tolist())):
        c, centres = int(round(column)), []
        for r in range(max(0, height - int(band)), height):
            row = mask[r]
            if not row[c]:
                continue
            left = c - int(np.argmin(row[c::-1])) if not row[:c + 1].all() else 0
            right = c + int(np.argmin(row[c:])) if not row[c:].all() else width - 1
            weight = cover[r, left:right + 1].astype(np.float64)
            if weight.sum() > 0:
                centres.append(float(weight @ np.arange(left, right + 1)) / weight.sum())
        if centres:
            out[k] = float(np.median(centres))
    return out


def _edges(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, ...]:
    """8-neighbour edges of the skeleton pixels (each once) and their lengths [px]."""
    index = np.full((shape[0] + 2, shape[1] + 2), -1, np.int64)  # padded: no bounds checks
    index[rows + 1, cols + 1] = np.arange(rows.size)
    src, dst, weight = [], [], []
    for dr, dc, w in NEIGHBOURS:
        other = index[rows + 1 + dr, cols + 1 + dc]
        has = other >= 0
        src.append(np.flatnonzero(has))
        dst.append(other[has])
        weight.append(np.full(int(has.sum()), w))
    return np.concatenate(src), np.concatenate(dst), np.concatenate(weight)


def _ancestors(pred: np.ndarray, steps: int) -> np.ndarray:
    """Each pixel's ancestor ``steps`` up its path (or its base, if nearer)."""
    ancestor = np.arange(pred.size)
    for _ in range(steps):
        up = pred[ancestor]
        ancestor = np.where(up >= 0, up, ancestor)
    return ancestor


def _chord_lengths(order: np.ndarray, dist: np.ndarray, ancestor: np.ndarray,
                   rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Arc length from the floor: a pixel's ancestor's plus the straight distance to it
    (a base keeps its height from the Dijkstra source)."""
    chord = np.hypot((rows - rows[ancestor]).astype(float), (cols - cols[ancestor]).astype(float))
    out, anc, chord = dist.tolist(), ancestor.tolist(), chord.tolist()
    for p in order.tolist():
        if anc[p] != p:
            out[p] = out[anc[p]] + chord[p]
    return np.asarray(out)


def _turning(ancestor: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Per pixel, the sharpest turn [rad] a path makes there: the angle between the chord
    arriving from ``TURN_PX`` steps back and each chord leaving to ``TURN_PX`` ahead."""
    a = ancestor
    b = ancestor[a]
    use = (a != np.arange(a.size)) & (b != a)
    q, a, b = np.flatnonzero(use), a[use], b[use]
    u = np.column_stack((rows[a] - rows[b], cols[a] - cols[b])).astype(float)
    v = np.column_stack((rows[q] - rows[a], cols[q] - cols[a])).astype(float)
    cos = (u * v).sum(axis=1) / np.maximum(np.hypot(*u.T) * np.hypot(*v.T), 1e-9)
    turning = np.zeros(rows.size)
    np.maximum.at(turning, a, np.arccos(np.clip(cos, -1.0, 1.0)))
    return turning


def _prune(order: np.ndarray, pred: np.ndarray, arc: np.ndarray, degree: np.ndarray,
           radius: np.ndarray, roots: np.ndarray, base: np.ndarray, spur_px: float,
           params: TreeParams) -> tuple[np.ndarray, list[int], int]:
    """Remove spurs: end branches shorter than ``spur_px`` or ``spur_radii`` radii of the
    stem they leave whose end is not thinner than ``spur_taper`` of that radius, and every
    end point in a stem's ``base`` (thinning runs a branch into each corner of a stem's square
    cut end: they narrow to their ends as a shoot does, but no shoot grows down into the
    floor). Returns (removed pixels, kept end points, spurs removed)."""
    n = pred.size
    is_root = np.zeros(n, bool)
    is_root[roots] = True
    branching = (degree >= 3) | is_root
    anchor = [-1] * n  # the nearest junction (or base) towards the base
    pred_list = pred.tolist()
    for p in order.tolist():
        anchor[p] = p if branching[p] else anchor[pred_list[p]]
    removed = np.zeros(n, bool)
    ends, pruned = [], 0
    for p in order[degree[order] <= 1].tolist():
        if is_root[p]:
            continue
        a = anchor[p]
        short = not is_root[a] and arc[p] - arc[a] < max(spur_px, params.spur_radii * radius[a])
        if base[p] or (short and radius[p] > params.spur_taper * radius[a]):
            pruned += 1
            while p != a:
                removed[p] = True
                p = pred_list[p]
        else:
            ends.append(p)
    return removed, ends, pruned
