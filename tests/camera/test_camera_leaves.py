"""Leaves are cut off the shoots: known answers on tiny masks drawn here.

Same grid as test_camera_skeleton (2 mm pixels over 0.2 m, nodes every 0.05 m): a stem 12 mm
wide and leaves drawn as a petiole 2 mm wide and a blade (a filled ellipse) 16 mm wide.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from growspace_camera.leaves import cut_leaves
from growspace_camera.markers import MarkerLayout
from growspace_camera.measure import Target
from growspace_camera.messages import measurement_msg
from growspace_camera.pipeline import Pipeline
from growspace_camera.twin import PhotoTwin, Variation
from test_camera_skeleton import GRID, mask_of, near, tree_of
from test_camera_vision import grown_by_oracle

STEM = [(0.1, 0.0), (0.1, 0.16)]


def blade(mask: np.ndarray, start: tuple[float, float], end: tuple[float, float],
          width_m: float = 0.016) -> np.ndarray:
    """``mask`` with a leaf blade from ``start`` to ``end`` (x, z in m), ``width_m`` wide."""
    (x0, z0), (x1, z1) = start, end
    centre = ((x0 + x1) / 2 / GRID.pixel_m, (0.2 - (z0 + z1) / 2) / GRID.pixel_m)
    size = (float(np.hypot(x1 - x0, z1 - z0) / GRID.pixel_m), width_m / GRID.pixel_m)
    angle = float(-np.degrees(np.arctan2(z1 - z0, x1 - x0)))
    out = mask.astype(np.uint8)
    cv2.ellipse(out, (centre, size, angle), 1, -1)  # a rotated rectangle's inscribed ellipse
    return out.astype(bool)


def leafy(*leaves: tuple[tuple[float, float], tuple[float, float], tuple[float, float]],
          stem: list[tuple[float, float]] = STEM) -> np.ndarray:
    """A stem with leaves, each (node, petiole end, blade end)."""
    mask = mask_of(stem)
    for node, base, end in leaves:
        mask |= mask_of([node, base], width_m=0.002)
        mask = blade(mask, base, end)
    return mask


def test_a_leaf_on_a_petiole_is_not_a_tip_and_its_end_is_a_leaf_tip():
    mask = leafy(((0.1, 0.07), (0.12, 0.08), (0.17, 0.10)))
    tree = tree_of(mask)
    assert tree.plants == 1 and tree.tips.size == 1
    assert near(tree.nodes[tree.tips], (0.1, 0.16))  # the shoot
    assert len(tree.leaf_tips) == 1 and near(tree.leaf_tips, (0.17, 0.10), 0.012)
    assert not np.any(tree.nodes[:, 0] > 0.115)  # no node out on the leaf
    # Turned off, the leaf is a branch with a tip at its end, as before.
    whole = tree_of(mask, leaf_widening=0.0)
    assert whole.tips.size == 2 and len(whole.leaf_tips) == 0


def test_a_leaf_at_a_shoots_end_leaves_the_tip_at_the_shoots_end():
    # The shoot ends at 0.13; a petiole of 1.5 cm then a blade carry its skeleton 8 cm on.
    mask = leafy(((0.1, 0.13), (0.11, 0.14), (0.16, 0.17)), stem=[(0.1, 0.0), (0.1, 0.13)])
    tree = tree_of(mask)
    assert tree.tips.size == 1
    tip = tree.nodes[tree.tips[0]]
    assert np.hypot(*(tip - (0.1, 0.13))) < 0.01, tip  # within the bench's 1 cm
    assert len(tree.leaf_tips) == 1
    whole = tree_of(mask, leaf_widening=0.0)
    assert np.hypot(*(whole.nodes[whole.tips[0]] - (0.1, 0.13))) > 0.03  # out on the leaf


def test_a_leaf_no_wider_than_its_shoots_base_is_cut_off_the_shoots_end():
    # A side shoot 8 mm wide ends at (0.14, 0.11); a petiole then a blade only as wide as the
    # shoot carry its skeleton on. The blade is the outer half's widest stretch, not the whole
    # branch's: the shoot's base is as wide, and judged by that the leaf went uncut.
    mask = mask_of(STEM) | mask_of([(0.1, 0.08), (0.14, 0.11)], width_m=0.008)
    mask |= mask_of([(0.14, 0.11), (0.155, 0.12)], width_m=0.002)
    mask = blade(mask, (0.155, 0.12), (0.195, 0.145), width_m=0.008)
    tree = tree_of(mask)
    assert tree.tips.size == 2 and len(tree.leaf_tips) == 1
    assert near(tree.nodes[tree.tips], (0.14, 0.11), 0.008), tree.nodes[tree.tips]
    assert near(tree.leaf_tips, (0.195, 0.145), 0.012)


def test_a_blade_whose_base_lies_on_the_stem_is_a_leaf_by_its_wide_end():
    # No petiole and no narrow base: the blade (2.4 cm wide) starts at the stem's edge, so
    # nothing narrower comes before its widest part; its end is wider than a shoot's.
    mask = blade(mask_of(STEM), (0.105, 0.07), (0.165, 0.10), width_m=0.024)
    tree = tree_of(mask)
    assert tree.plants == 1 and tree.tips.size == 1
    assert near(tree.nodes[tree.tips], (0.1, 0.16))  # the shoot
    assert len(tree.leaf_tips) == 1 and near(tree.leaf_tips, (0.165, 0.10), 0.015)
    assert not np.any(tree.nodes[:, 0] > 0.115)  # no node out on the leaf
    # The widening rule alone does not see it: its end is a tip.
    assert tree_of(mask, leaf_end_m=0.0).tips.size == 2


def test_a_pointed_blade_on_a_shoots_end_is_cut_whole_not_at_its_point():
    # An end branch that is a blade alone (radii along it, in pixels, from a twin photo: it
    # leaves the junction at a shoot's end 4.6 px wide, widens to 6.4, then narrows to its
    # point). It never narrows below its start before the blade, so only its wide end marks
    # it; the shoot ends where it was last thin *before* the blade, here nowhere: the whole
    # branch is leaf. Taking the thin point beyond the blade left a false tip there.
    radius = np.array([4.6, 4.2, 3.8, 3.8, 4.6, 4.8, 5.1, 4.6, 5.2, 5.7, 6.4, 6.4, 6.4, 6.4,
                       5.7, 5.2, 4.6, 4.6, 3.8, 2.9, 1.9, 1.4])
    shoots, leaves, removed = _cut_one_branch(radius)
    assert shoots == [] and leaves == [radius.size - 1]
    assert removed[1:].all() and not removed[0]


def test_a_shoot_passing_a_blade_that_lies_on_it_keeps_its_tip(monkeypatch):
    # A side shoot 6 mm wide with a blade (1.6 cm wide) lying along it halfway out, then 4 cm
    # more of shoot: a blade narrows to its point, so a branch that stays thin this long past
    # its widest part is a shoot, and its tip is the shoot's (cut at the blade, it was a leaf
    # tip and the shoot ended 8 cm short).
    shoot = [(0.1, 0.06), (0.19, 0.15)]
    mask = blade(mask_of(STEM) | mask_of(shoot, width_m=0.006), (0.125, 0.085), (0.16, 0.12))
    tree = tree_of(mask)
    assert tree.tips.size == 2 and len(tree.leaf_tips) == 0
    assert near(tree.nodes[tree.tips], (0.19, 0.15))
    monkeypatch.setattr('growspace_camera.leaves.BLADE_TAIL', np.inf)
    cut = tree_of(mask)  # (without the rule: cut at the blade, the end a leaf tip)
    assert not near(cut.nodes[cut.tips], (0.19, 0.15)) and near(cut.leaf_tips, (0.19, 0.15))


def test_a_thick_stem_that_narrows_to_a_blunt_shoot_is_no_blade():
    # Radii (px) along an end branch of an old-twin photo: a leading stem 4.8 cm wide for
    # 12 cm, then a shoot 1.9 cm wide for 4 cm to its end. Wide at its end and never thin
    # before, and only 4.8 times as long as it is wide, it was taken whole for a blade and the
    # plant's lead was lost (reward 0.33 for the simulator's 1.0); a blade narrows to its
    # point past its widest part, and this goes on for 2 of its widths.
    radius = np.array([9.4, 9.8, 9.3, 9.7, 10.1, 9.6, 10.1] + [10.5] * 9 + [10.1]
                      + [9.6] * 30 + [8.6, 8.2, 7.8, 6.8, 6.4, 6.0, 5.5, 5.1, 4.6, 4.2]
                      + [3.8] * 16 + [4.2, 4.6, 4.6, 4.2, 3.8, 3.8, 2.9])
    shoots, leaves, removed = _cut_one_branch(radius)
    assert shoots == [radius.size - 1] and leaves == [] and not removed.any()


def _cut_one_branch(radius: np.ndarray) -> tuple[list[int], list[int], np.ndarray]:
    """``cut_leaves`` on one end branch, a pixel per radius, leaving a junction at pixel 0
    (petiole_m 10 px, leaf_end_m 7.6 px): (shoot ends, leaf ends, pixels removed)."""
    n = radius.size
    pred = np.arange(-1, n - 1)
    pred[0] = 99  # (the junction's own path goes on towards a base, off this array)
    branching = np.zeros(n, bool)
    branching[0] = True
    removed = np.zeros(n, bool)
    shoots, leaves = cut_leaves(pred, np.arange(n, dtype=float), radius, branching, [n - 1],
                                removed, 1.5, 10.0, 3.8)
    return shoots, leaves, removed


@pytest.mark.parametrize('end, is_leaf', [((0.17, 0.17), False), ((0.13, 0.10), True)])
def test_a_wide_end_branch_is_a_leaf_only_if_shaped_as_a_blade(end, is_leaf):
    # A side branch 2 cm wide, as wide as leaf_end_m takes for a blade, with no narrower
    # stretch: 5.8 cm long it is a blade (a leaf tip); 13.9 cm long (six times its width) it
    # is a thick shoot with its tip, no leaf, however wide its end.
    mask = (mask_of([(0.1, 0.0), (0.1, 0.05)], width_m=0.024)
            | mask_of([(0.1, 0.05), end], width_m=0.02)
            | mask_of([(0.1, 0.05), (0.05, 0.12)]))
    tree = tree_of(mask)
    assert near(tree.nodes[tree.tips], (0.05, 0.12))
    assert near(tree.nodes[tree.tips], end) is not is_leaf
    assert len(tree.leaf_tips) == int(is_leaf)


@pytest.mark.parametrize('width_m', [0.006, 0.012, 0.02])
def test_shoots_that_narrow_to_their_tips_keep_them(width_m):
    # A fork whose shoots taper to their tips, as the simulator's and real stems do: no leaf.
    mask = np.zeros(GRID.shape, np.uint8)
    px = width_m / GRID.pixel_m
    for (x0, z0), (x1, z1), w0, w1 in (((0.1, 0.0), (0.1, 0.1), 1.0, 1.0),
                                       ((0.1, 0.1), (0.05, 0.17), 0.8, 0.35),
                                       ((0.1, 0.1), (0.16, 0.16), 0.8, 0.35)):
        a = np.array((x0, 0.2 - z0)) / GRID.pixel_m
        b = np.array((x1, 0.2 - z1)) / GRID.pixel_m
        normal = np.array((b - a)[::-1]) * (1, -1) / np.hypot(*(b - a))
        quad = np.array([a + normal * w0 * px / 2, b + normal * w1 * px / 2,
                         b - normal * w1 * px / 2, a - normal * w0 * px / 2])
        cv2.fillConvexPoly(mask, np.round(quad * 16).astype(np.int32), 1, cv2.LINE_8, 4)
    tree = tree_of(mask.astype(bool))
    assert tree.tips.size == 2 and len(tree.leaf_tips) == 0
    assert near(tree.nodes[tree.tips], (0.05, 0.17), 0.008)
    assert near(tree.nodes[tree.tips], (0.16, 0.16), 0.008)


def test_a_blade_straight_off_a_stem_is_all_leaf():
    # No petiole: the blade's own narrow base leaves the stem's edge, and it widens from there.
    mask = blade(mask_of(STEM), (0.105, 0.08), (0.17, 0.11), width_m=0.024)
    tree = tree_of(mask)
    assert tree.tips.size == 1 and near(tree.nodes[tree.tips], (0.1, 0.16))
    assert len(tree.leaf_tips) == 1


def test_a_plant_holding_only_leaves_is_still_a_plant():
    # A seedling: a short stem and two leaves on petioles, no shoot tip of its own beyond.
    mask = leafy(((0.1, 0.07), (0.085, 0.08), (0.04, 0.11)),
                 ((0.1, 0.07), (0.115, 0.08), (0.16, 0.11)), stem=[(0.1, 0.0), (0.1, 0.07)])
    tree = tree_of(mask, min_stem_m=0.03)
    assert tree.plants == 1
    assert len(tree.leaf_tips) == 2


def measured_on_a_rig(challenge: str, setting: str, steps: int, factor: str):
    """A chamber grown ``steps`` steps by its oracle (seed 1000), photographed on a rig with
    ``factor`` alone (the bench's photo of that step), and its measurement."""
    grown = grown_by_oracle(challenge, setting, seed=1000, steps=steps)
    c = grown.sim.chamber
    shot = PhotoTwin(MarkerLayout()).photo(c, seed=100_000 + steps,
                                           variation=Variation.only(factor), rig_seed=1000)
    m = Pipeline().measure(shot.bgr, grown.cfg, c.light.copy(), Target(c.target), c.steps)
    assert m.ok, m.error
    return grown, m


def test_a_leafy_twin_photo_reports_its_leaves_in_the_measurement_message():
    _, m = measured_on_a_rig('control', 'easy', 30, 'leaves')
    msg = measurement_msg(m, 0, 30, 'chamber', 0.0025)
    assert msg.leaves == len(m.tree.leaf_tips) == m.confidence.leaves > 0
    assert msg.tips == m.tree.tips.size


def test_a_young_plants_bent_stem_is_not_cut_off_as_a_leaf():
    # Fairness hard, 24 steps: the far plant is a short stem bent once; where it bends the mask
    # widens, as a blade does beyond a petiole. Cut off as a leaf, its plant was a bare base
    # scored 0 (the simulator's 0.052).
    grown, m = measured_on_a_rig('fairness', 'hard', 24, 'lamp_bands')
    assert np.bincount(m.tree.plant[m.tree.plants:]).min() >= 2  # both plants grew nodes
    assert abs(m.reward - grown.reward) < 0.005
