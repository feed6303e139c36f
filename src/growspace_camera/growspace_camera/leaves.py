"""Leaves on the skeleton: end branches that end in a blade, not in a shoot tip.

The simulator's plant has no leaves: its tips are shoot tips, and its drawing is its branches.
A real plant's leaf thins into a skeleton end branch as a shoot does, so measured as one it is
a false tip, and a leaf at a shoot's end carries that shoot's tip out to the leaf's end.

A shoot keeps its width or narrows towards its tip (the simulator thickens a segment with its
descendants and draws a tip narrower still; real stems do the same). A blade is wider than the
stalk that holds it (a petiole, or its own narrow base). So an end branch, walked from the stem
it leaves (past that stem's own radius) out to its end, ends in a leaf when the widest part of
its stretch beyond ``BLADE_FROM`` of its length (the one nearest the end) is ``leaf_widening``
times, and at least ``LEAF_RISE_PX`` more than, the narrowest radius before it.

A blade whose base lies on the stem, or on a petiole as wide, has no narrower stalk before
it; but a shoot's end is thin (the simulator's tips are its thinnest segments, 1.3 cm wide
at its defaults), so an end branch ``leaf_end_m`` (1.9 cm) wide within ``END_PX`` of its end
is a blade too, its stalk ending where the branch was last a shoot's width before the blade,
or, with no such stretch, the whole branch if it is shaped as a blade (at most
``BLADE_ASPECT`` times as long as it is wide: a long thick stem is a shoot, whatever its end).

Either way, a blade narrows to its point: a branch that stays as wide as its stalk (or, taken
whole, as half the blade) for more than ``BLADE_TAIL`` blade widths past its widest part is a
shoot, one that a blade lies on or a thick stem narrowing to a blunt end, and no leaf.

The branch is cut where its narrowest stretch before the blade (the petiole, at most
``petiole_m`` of it) begins: the shoot ends there, and the branch's end is reported as a leaf
tip. Where what is left is shorter than ``petiole_m``, the whole branch is the leaf, unless it
rises from a stem base: a plant's first stem is never all leaf (where it bends, the mask
widens as it does beyond a petiole).

Measured on the twin's leafy photos (tuning combinations; docs/hardware.md). Left as they are:
a blade lying along a stem (no end branch of its own) and a leaf no wider than what holds it.
A stem's cut or broken end as wide as ``leaf_end_m`` is taken for a blade: set it above the
widest shoot end of the plants grown.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter

LEAF_RISE_PX = 1.0  # a blade is at least this much wider than its petiole (the distance
# transform's radii step by about 0.96 px across a stem)
BLADE_FROM = 0.45  # of the branch's length: a blade's widest part lies beyond this
SMOOTH_PX = 5  # the radius is read as a median over this many path pixels
END_PX = 6  # a blade end is wide within this many path pixels of the end (1.5 cm)
SHOOT_OF_BLADE = 0.6  # a blade is cut where the branch is back to this part of blade_px
BLADE_TAIL = 1.0  # a blade narrows to its point within this many blade widths of its widest
# part (the twin's within 0.4; pointed real blades within about 1): a branch that goes on for
# longer is a shoot (one a blade lies on, or a thick stem narrowing to a blunt end)
BLADE_ASPECT = 5.0  # a blade is at most this many times as long as it is wide (simple leaves
# 2-4 times: the twin's, and a long thick stem's end branch is no leaf however wide its end)


def cut_leaves(pred: np.ndarray, arc: np.ndarray, radius: np.ndarray, branching: np.ndarray,
               ends: list[int], removed: np.ndarray, widening: float,
               petiole_px: float, blade_px: float) -> tuple[list[int], list[int]]:
    """Cut the leaves off the end branches (see the module docstring).

    Args:
        pred: Predecessor of each pixel on its path (-1 at a base).
        arc: Arc length from the floor per pixel [px].
        radius: Distance to the mask's edge per pixel [px].
        branching: Per pixel, a junction or a base (an end branch leaves from one).
        ends: The end points after spur pruning.
        removed: Per pixel, pruned; the leaves' pixels are set too (in place).
        widening: ``leaf_widening``; 0: no leaves are cut.
        petiole_px: ``petiole_m`` in pixels.
        blade_px: Half of ``leaf_end_m`` in pixels (a radius); 0: no blade ends.

    Returns:
        (the end points: shoots' ends, cut ones included; the leaves' end points).
    """
    shoots, leaves = [], []
    pred_list, branching_list = pred.tolist(), branching.tolist()  # (walked pixel by pixel)
    for end in ends:
        path = [end]
        while not branching_list[path[-1]] and pred_list[path[-1]] >= 0:
            path.append(pred_list[path[-1]])
        path.reverse()  # from the junction (or base) out to the end
        cut = _leaf_cut(path, arc, radius, widening, petiole_px, blade_px)
        whole = cut is not None and (cut == 0 or arc[path[cut]] - arc[path[0]] < petiole_px)
        # A plant's first stem is no leaf: a branch rising from its base (no junction on the
        # way, as a young plant's stem) keeps it; a bend there widens the mask, not a blade.
        if cut is None or (whole and pred[path[0]] < 0):
            shoots.append(end)
            continue
        leaves.append(end)
        for p in path[1:] if whole else path[cut + 1:]:
            removed[p] = True
        if not whole:
            shoots.append(path[cut])
    return shoots, leaves


def _leaf_cut(path: list[int], arc: np.ndarray, radius: np.ndarray, widening: float,
              petiole_px: float, blade_px: float) -> int | None:
    """Index into ``path`` where a leaf begins (0: the whole branch), or None (a shoot)."""
    s = arc[path] - arc[path[0]]
    r = radius[path]
    blunt = blade_px > 0 and r[s >= s[-1] - END_PX].max() >= blade_px
    own = np.flatnonzero(s >= r[0])  # beyond the radius of the stem it leaves
    if own.size < 2:
        return 0 if blunt else None
    s = s[own]
    # A blade is wide along a stretch: a pixel or two of bulge where a crossing branch or a
    # corner touches the path is not one (a median over ``SMOOTH_PX`` along the path).
    r = median_filter(r[own], size=SMOOTH_PX, mode='nearest')
    # The blade: the widest stretch of the branch's outer part, the one nearest its end (a
    # shoot tapers, so its base can be as wide as, or wider than, the leaf at its end).
    # (arc lengths summed over chords wobble by a pixel: not sorted, so no searchsorted)
    outer = np.flatnonzero(s >= BLADE_FROM * s[-1])  # never empty: it holds the end
    widest = int(outer[outer.size - 1 - int(np.argmax(r[outer][::-1]))])
    narrow = widest - int(np.argmin(r[widest::-1]))  # the last narrowest: nearest the blade
    if not (widening > 0 and r[widest] >= widening * r[narrow]
            and r[widest] - r[narrow] >= LEAF_RISE_PX):
        if not blunt:
            return None
        # No narrower stalk before the widest part, but an end as wide as a blade: its base
        # lies on the stem (or on a petiole as wide); the shoot ends where it is last thin.
        # (only before the widest part: a pointed blade is thin at its own end too)
        thin = np.flatnonzero(r[:widest] <= SHOOT_OF_BLADE * blade_px)
        if thin.size == 0:  # the whole branch is a blade, if shaped as one: a shoot is longer
            blade = s[-1] <= BLADE_ASPECT * 2.0 * r[widest] \
                and _narrows(s, r, widest, 0.5 * r[widest])
            return 0 if blade else None
        narrow = int(thin[-1])
    stalk = r[narrow] + 0.5 * LEAF_RISE_PX  # as wide as the stalk, within half a rise
    if not _narrows(s, r, widest, stalk):
        return None  # a shoot that a blade lies on goes on as thin as before it
    start = narrow  # back along the petiole (at most petiole_m of it) to the shoot's end
    while start > 0 and r[start - 1] <= stalk and s[narrow] - s[start - 1] <= petiole_px:
        start -= 1
    return int(own[start])


def _narrows(s: np.ndarray, r: np.ndarray, widest: int, level: float) -> bool:
    """Whether the branch ends within ``BLADE_TAIL`` blade widths of where it was last wider
    than ``level`` past its widest part, as a blade narrows to its point."""
    last = widest + int(np.flatnonzero(r[widest:] > level).max(initial=0))
    return bool(s[-1] - s[last] <= BLADE_TAIL * 2.0 * r[widest])
