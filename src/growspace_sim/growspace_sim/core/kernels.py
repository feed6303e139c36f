"""The compiled growth step: the SCA update of ``Chamber`` as numba kernels over its arrays.

A growing step used to be a few dozen numpy calls of about 1 us each on arrays of tens of
elements; here each part is one loop compiled by numba (``@njit(cache=True)``: compiled on the
first call of a fresh install, then loaded from the on-disk cache beside this file, or from
numba's user-wide cache when that directory is read-only).

The kernels compute exactly what the numpy version computed, bit for bit, so seeded episodes
stay the same. Two numpy details matter for that:

- ``np.abs`` of a complex number is not libm's ``hypot``: numpy's SIMD loop computes
  ``larger * sqrt(ratio * ratio + 1)`` with ``ratio = smaller / larger`` and a fused
  multiply-add where the CPU has one. ``_cabs`` is that formula, with LLVM allowed to fuse
  (``contract``) in it alone.
- A complex divided by a real is a complex division by ``d + 0j``: numpy multiplies by
  ``1 / d`` (Smith's method) instead of dividing. ``_divide_real`` writes the same operations.

Positions are complex ``x + 1j * z`` in metres, as in ``core.chamber``.
"""

from __future__ import annotations

import math

from numba import njit
import numpy as np

_DIRECTION_EPS = 1e-12  # a sum of unit vectors this short has no direction: the bud stays


@njit(cache=True, fastmath={'contract'})
def _cabs(re: float, im: float) -> float:
    """|re + i im| exactly as numpy's ``absolute`` loop computes it."""
    re, im = abs(re), abs(im)
    larger, smaller = max(re, im), min(re, im)
    if larger == 0.0 or math.isinf(smaller):
        return larger
    ratio = smaller / larger
    return math.sqrt(ratio * ratio + 1.0) * larger


@njit(cache=True, error_model='numpy')
def _divide_real(re: float, im: float, d: float) -> complex:
    """(re + i im) / (d + 0i) with numpy's operations (d > 0 here)."""
    ratio = 0.0 / d
    scale = 1.0 / (d + 0.0 * ratio)
    return complex((re + im * ratio) * scale, (im - re * ratio) * scale)


@njit(cache=True)
def _bisect(x: np.ndarray, value: float, right: bool) -> int:
    """``np.searchsorted(x, value, 'right' if right else 'left')`` on sorted x."""
    low, high = 0, x.size
    while low < high:
        mid = (low + high) // 2
        if x[mid] < value or (right and x[mid] == value):
            low = mid + 1
        else:
            high = mid
    return low


@njit(cache=True, error_model='numpy')
def grow(photons: np.ndarray, photon_x: np.ndarray, nearest_node: np.ndarray,
         nearest_distance: np.ndarray, available: np.ndarray, n_nodes: int, low: float,
         high: float, spot: bool, centre: complex, radius: float, max_branching: int,
         buds: np.ndarray, pull: np.ndarray, strength: np.ndarray, pos: np.ndarray,
         branch_length: float, width: float, height: float, new: np.ndarray) -> tuple[int, int]:
    """Find the buds the lit photons attract and, if at most ``max_branching``, sprout them.

    Lit: x in [low, high] (and within ``radius`` of ``centre`` for a spotlight) and available.
    Each lit photon pulls its nearest node along the unit vector towards it.

    Returns:
        (buds, grown): the number of buds (nodes whose pull has a direction, listed in
        ascending order in ``buds``; ``pull`` and ``strength`` hold their sums and lengths),
        and the new tips ``sprout`` kept, or -1 when there are more buds than may grow.
    """
    pull[:n_nodes] = 0.0
    start, end = _bisect(photon_x, low, False), _bisect(photon_x, high, True)
    for i in range(start, end):
        if not available[i]:
            continue
        p = photons[i]
        if spot and not _cabs(p.real - centre.real, p.imag - centre.imag) <= radius:
            continue
        node = nearest_node[i]
        pull[node] += _divide_real(p.real - pos[node].real, p.imag - pos[node].imag,
                                   nearest_distance[i])
    count = 0
    for node in range(n_nodes):
        strength[node] = _cabs(pull[node].real, pull[node].imag)
        if strength[node] > _DIRECTION_EPS:
            buds[count] = node
            count += 1
    if count > max_branching:
        return count, -1
    return count, sprout(buds[:count], pull, strength, pos, branch_length, width, height, new)


@njit(cache=True, error_model='numpy')
def sprout(buds: np.ndarray, pull: np.ndarray, strength: np.ndarray, pos: np.ndarray,
           branch_length: float, width: float, height: float, new: np.ndarray) -> int:
    """New tips one branch length from the buds along their pull; drop those outside.

    Returns:
        How many stay: ``buds`` and ``new`` hold them first, in their order.
    """
    kept = 0
    for k in range(buds.size):
        node = buds[k]
        p = pull[node]  # branch_length * p is a complex product by branch_length + 0j
        step = _divide_real(branch_length * p.real - 0.0 * p.imag,
                            branch_length * p.imag + 0.0 * p.real, strength[node])
        tip = pos[node] + step
        if 0.0 <= tip.real <= width and 0.0 <= tip.imag <= height:
            buds[kept] = node
            new[kept] = tip
            kept += 1
    return kept


@njit(cache=True)
def count_descendants(parents: np.ndarray, depth: np.ndarray, ancestors: np.ndarray,
                      descendants: np.ndarray, start: int, deep: bool) -> None:
    """Give the new nodes start.. their ancestor rows; add one descendant to every ancestor.

    A row holds the ``window`` nearest ancestors (1 + node, at column depth % window); a node
    deeper than that reaches the rest through the row of its oldest listed ancestor.
    """
    window = ancestors.shape[1]
    for k in range(parents.size):
        parent, node = parents[k], start + k
        row = ancestors[node]
        row[:] = ancestors[parent]
        parent_depth = depth[parent]
        row[parent_depth % window] = parent + 1
        for a in row:
            descendants[a] += 1  # [0] counts empty columns: unused
        if not deep or parent_depth < window:
            continue
        anchor = row[(parent_depth + 1) % window] - 1
        while True:
            anchor_row = ancestors[anchor]
            for a in anchor_row:
                descendants[a] += 1
            anchor_depth = depth[anchor]
            if anchor_depth <= window:
                break
            anchor = anchor_row[anchor_depth % window] - 1


@njit(cache=True)
def segment_points(a: complex, b: complex, t: np.ndarray, out: np.ndarray) -> None:
    """Points ``a + (b - a) * t`` along a segment, as numpy's complex arithmetic gives them."""
    dr, di = b.real - a.real, b.imag - a.imag
    for j in range(t.size):
        out[j] = complex(a.real + (dr * t[j] - di * 0.0), a.imag + (dr * 0.0 + di * t[j]))


@njit(cache=True)
def shade(canopy: np.ndarray, a: complex, b: complex, t: np.ndarray, points: np.ndarray,
          half: float, inv_column: float) -> None:
    """Raise the canopy (top of the plant per column) over the thickened segment a-b.

    Points sampled along the segment at most one column apart, each widened by half the
    thickness to both sides, mark the columns the segment covers.
    """
    segment_points(a, b, t, points)
    last = canopy.size - 1
    for j in range(t.size):
        top = points[j].imag + half
        for x in (points[j].real - half, points[j].real + half):
            column = min(max(int(x * inv_column), 0), last)
            if top > canopy[column]:
                canopy[column] = top


@njit(cache=True)
def rasterise(occupancy: np.ndarray, a: complex, b: complex, t: np.ndarray, points: np.ndarray,
              col_per_m: float, row_per_m: float, height: float) -> None:
    """Mark the image pixels that points sampled along segment a-b fall in."""
    segment_points(a, b, t, points)
    last = occupancy.shape[0] - 1
    for j in range(t.size):
        col = min(int(points[j].real * col_per_m), last)
        row = min(int((height - points[j].imag) * row_per_m), last)
        occupancy[row, col] = True


@njit(cache=True)
def mark_available(available: np.ndarray, photons: np.ndarray, column: np.ndarray,
                   nearest_distance: np.ndarray, canopy: np.ndarray, influence: float,
                   shading: bool) -> None:
    """Flag the photons that would attract if lit: a node within reach, nothing above."""
    for i in range(photons.size):
        available[i] = nearest_distance[i] < influence and (
            not shading or canopy[column[i]] <= photons[i].imag)


@njit(cache=True)
def update_photons(photons: np.ndarray, photon_x: np.ndarray, column: np.ndarray,
                   nearest_node: np.ndarray, nearest_distance: np.ndarray, new: np.ndarray,
                   first: int, kill: float) -> int:
    """Re-point photons to the new nodes (numbered from ``first``) where those are nearer and
    use up the photons closer than ``kill`` to one; the survivors move to the front, in order.

    Returns:
        The number of photons left.
    """
    left = 0
    for i in range(photons.size):
        p = photons[i]
        best, closest = np.inf, 0
        for j in range(new.size):  # ties go to the older node, as argmin does
            d = _cabs(p.real - new[j].real, p.imag - new[j].imag)
            if d < best:
                best, closest = d, j
        node, distance = nearest_node[i], nearest_distance[i]
        if best < distance:
            node, distance = first + closest, best
        if best >= kill:
            photons[left], photon_x[left], column[left] = p, photon_x[i], column[i]
            nearest_node[left], nearest_distance[left] = node, distance
            left += 1
    return left


@njit(cache=True)
def append(new: np.ndarray, parents: np.ndarray, start: int, photons: np.ndarray,
           photon_x: np.ndarray, column: np.ndarray, nearest_node: np.ndarray,
           nearest_distance: np.ndarray, available: np.ndarray, pos: np.ndarray,
           parent: np.ndarray, plant: np.ndarray, has_child: np.ndarray, depth: np.ndarray,
           ancestors: np.ndarray, descendants: np.ndarray, deep: bool,
           branch_counts: np.ndarray, has_target: bool, target: complex, nearest: np.ndarray,
           has_mask: bool, occupancy: np.ndarray, pixel_t: np.ndarray, col_per_m: float,
           row_per_m: float, height: float, canopy: np.ndarray, column_t: np.ndarray,
           half: float, inv_column: float, kill: float, influence: float,
           shading: bool) -> int:
    """Add nodes ``new`` (numbered from ``start``) with segments to ``parents`` and update what
    depends on them: descendants, the nearest approach to a point target, the plant's pixels
    for a shape target, the photons' nearest nodes, used-up photons, the canopy and which
    photons are available.

    Returns:
        The number of photons left (the survivors are the first ones of the photon arrays).
    """
    for k in range(new.size):
        node, up = start + k, parents[k]
        owner = plant[up]
        pos[node], parent[node], plant[node] = new[k], up, owner
        has_child[up] = True
        branch_counts[owner] += 1
        depth[node] = depth[up] + 1
        if has_target:
            nearest[owner] = min(nearest[owner], _cabs(new[k].real - target.real,
                                                       new[k].imag - target.imag))
    count_descendants(parents, depth, ancestors, descendants, start, deep)
    points = np.empty(max(pixel_t.size, column_t.size), np.complex128)
    for k in range(new.size):
        if has_mask:
            rasterise(occupancy, pos[parents[k]], new[k], pixel_t, points, col_per_m,
                      row_per_m, height)
    left = update_photons(photons, photon_x, column, nearest_node, nearest_distance, new,
                          start, kill)
    for k in range(new.size):
        shade(canopy, pos[parents[k]], new[k], column_t, points, half, inv_column)
    mark_available(available[:left], photons[:left], column[:left], nearest_distance[:left],
                   canopy, influence, shading)
    return left
