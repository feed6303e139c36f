"""Mask -> plants, nodes and tips: known answers on tiny masks drawn here.

The masks are 2 mm pixels over a 0.2 m square (100 x 100), stems drawn with OpenCV; node
spacing 0.05 m (the first node 0.05 m above the floor), so every answer is a few round
numbers.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from growspace_camera.errors import CameraError, NO_PLANT, PLANTS, UNEXPLAINED
from growspace_camera.measure import measured_state, Target
from growspace_camera.nodes import measure_tree, PlantTree
from growspace_camera.pipeline import (
    check_floating, check_loops, check_shares, PipelineParams)
from growspace_camera.segment import Grid
from growspace_camera.skeleton import TreeParams
from growspace_sim.core.config import SimConfig

GRID = Grid(0.2, 0.2, 0.002)
SPACING = 0.05


def mask_of(*polylines: list[tuple[float, float]], width_m: float = 0.012,
            grid: Grid = GRID) -> np.ndarray:
    """A mask with each polyline (x, z in m) drawn as a stem ``width_m`` wide, its last point
    the centre of a round end (as a twig's tip is round)."""
    mask = np.zeros(grid.shape, np.uint8)
    height_m = grid.shape[0] * grid.pixel_m
    for line in polylines:
        points = np.array([((x / grid.pixel_m - 0.5) * 16,
                            ((height_m - z) / grid.pixel_m - 0.5) * 16) for x, z in line],
                          np.int32)
        cv2.polylines(mask, [points], False, 1, int(round(width_m / grid.pixel_m)),
                      cv2.LINE_8, 4)
        cv2.circle(mask, tuple(int(v) for v in points[-1]),
                   int(round(0.5 * width_m / grid.pixel_m * 16)), 1, -1, cv2.LINE_8, 4)
    return mask.astype(bool)


def tree_of(mask: np.ndarray, **params):
    return measure_tree(mask, GRID, SPACING, SPACING, TreeParams(**params))


def thick_tree_of(mask: np.ndarray, **params):
    """``tree_of`` for stems 2 cm wide or more: their ends are as wide as the default
    ``leaf_end_m`` takes for a leaf blade, so that rule is off."""
    return tree_of(mask, leaf_end_m=0.0, **params)


def near(points: np.ndarray, point: tuple[float, float], tol: float = 0.004) -> bool:
    return bool(np.any(np.hypot(*(np.asarray(points) - point).T) < tol))


def test_a_straight_stem_is_one_plant_with_nodes_every_spacing_and_its_tip():
    tree = tree_of(mask_of([(0.1, 0.0), (0.1, 0.15)]))
    assert tree.plants == 1 and tree.tips.size == 1 and tree.tips_pruned == 0
    assert tree.nodes[0] == pytest.approx((0.1, 0.0), abs=0.002)  # the root, on the floor
    for z in (0.05, 0.10):
        assert near(tree.nodes, (0.1, z))
    assert tree.nodes[tree.tips[0]] == pytest.approx((0.1, 0.15), abs=0.003)
    assert tree.parent[0] == -1 and np.all(tree.parent[1:] < np.arange(1, len(tree.parent)))
    assert set(tree.plant) == {0}


def test_a_corner_gets_its_node_where_the_stem_turns():
    tree = tree_of(mask_of([(0.1, 0.0), (0.1, 0.1), (0.16, 0.13)]))
    assert tree.tips.size == 1
    assert near(tree.nodes, (0.1, 0.1), 0.003)  # the corner, not a rounded-off point
    assert tree.nodes[tree.tips[0]] == pytest.approx((0.16, 0.13), abs=0.003)


@pytest.mark.parametrize('bend_deg', [10.0, 12.0])
def test_a_corner_after_a_gentle_bend_is_placed_by_the_segment_next_to_it(bend_deg):
    # The stem bends by less than corner_deg at its first node (a node placed between, no
    # corner), then turns 80 degrees. Its line is fitted to the segment next to the corner:
    # fitted to the whole run it is their mean, and the corner moves 3-4 mm along the turn.
    bend = np.radians(bend_deg)
    corner = (0.1 + 0.05 * np.sin(bend), 0.05 + 0.05 * np.cos(bend))
    tree = tree_of(mask_of([(0.1, 0.0), (0.1, 0.05), corner, (corner[0] + 0.05, corner[1])]))
    assert tree.tips.size == 1 and len(tree.nodes) == 4
    assert near(tree.nodes, corner, 0.0015)


def cover_of(polyline: list[tuple[float, float]], width_m: float = 0.012,
             scale: int = 8) -> np.ndarray:
    """Plant cover per pixel of a round-ended stem (the share of each pixel it covers),
    drawn anti-aliased ``scale`` times finer and averaged down."""
    shape = (GRID.shape[0] * scale, GRID.shape[1] * scale)
    fine = np.zeros(shape, np.uint8)
    points = np.array([(x / GRID.pixel_m * scale, (0.2 - z) / GRID.pixel_m * scale)
                       for x, z in polyline])
    fixed = np.round(points * 16).astype(np.int32)
    cv2.polylines(fine, [fixed], False, 255, int(round(width_m / GRID.pixel_m * scale)),
                  cv2.LINE_AA, 4)
    cv2.circle(fine, tuple(int(v) for v in fixed[-1]),
               int(round(0.5 * width_m / GRID.pixel_m * scale * 16)), 255, -1, cv2.LINE_AA, 4)
    return cv2.resize(fine.astype(np.float32) / 255, GRID.shape[::-1],
                      interpolation=cv2.INTER_AREA)


def test_a_tip_is_placed_across_its_shoot_by_the_plant_cover():
    # Shoots at 10-40 degrees, each a fraction of a pixel further right: the mask's farthest
    # pixels are whole ones and thinning hooks the skeleton's end to a side, so across the
    # shoot the mask alone places a tip up to 0.8 of a pixel off; the cover's centroid does not.
    off = {True: [], False: []}
    for dx in np.linspace(0.0, 0.002, 5):
        for angle in np.radians([10.0, 25.0, 40.0]):
            fork, tip = (0.1 + dx, 0.1), (0.1 + dx + 0.06 * np.sin(angle),
                                          0.1 + 0.06 * np.cos(angle))
            cover = cover_of([(0.1 + dx, 0.0), fork, tip])
            axis = np.subtract(tip, fork) / 0.06
            for with_cover in (True, False):
                tree = measure_tree(cover > 0.5, GRID, SPACING, SPACING, TreeParams(),
                                    cover if with_cover else None)
                error = tree.nodes[tree.tips] - tip
                error = error[np.argmin(np.hypot(*error.T))]
                off[with_cover].append(abs(axis[0] * error[1] - axis[1] * error[0]))
    assert np.mean(off[True]) < 0.0005 < np.mean(off[False]), off
    assert np.max(off[True]) < 0.0015


def test_a_tapered_tip_is_placed_along_its_shoot_by_the_plant_cover():
    # As the twin draws a simulator tip: a shoot narrowing from 12 mm to 4.2 mm, a round end
    # 2.1 mm in radius at the node, blurred by 0.7 px. Along the shoot the tip lies within
    # 1.5 mm of the node (mean 0.8) at any angle and sub-pixel offset.
    scale, k = 8, 8 / GRID.pixel_m

    def fine(point: tuple[float, float]) -> np.ndarray:
        return np.array([point[0] * k, (0.2 - point[1]) * k])

    errors = []
    for dx in np.linspace(0.0, 0.002, 5):
        for angle in np.radians([0.0, 15.0, 30.0, 45.0]):
            base, fork = (0.1 + dx, 0.0), (0.1 + dx, 0.1)
            tip = (fork[0] + 0.06 * np.sin(angle), 0.1 + 0.06 * np.cos(angle))
            canvas = np.zeros((GRID.shape[0] * scale, GRID.shape[1] * scale), np.uint8)
            for a, b, half_a, half_b in ((base, fork, 0.006, 0.006), (fork, tip, 0.006, 0.0021)):
                a, b = fine(a), fine(b)
                normal = np.array([-(b - a)[1], (b - a)[0]]) / np.hypot(*(b - a))
                quad = [a + half_a * k * normal, b + half_b * k * normal,
                        b - half_b * k * normal, a - half_a * k * normal]
                cv2.fillConvexPoly(canvas, np.round(np.array(quad) * 16).astype(np.int32), 255,
                                   cv2.LINE_AA, 4)
                cv2.circle(canvas, tuple(int(v) for v in np.round(b * 16)),
                           int(half_b * k * 16), 255, -1, cv2.LINE_AA, 4)
            cover = cv2.resize(canvas.astype(np.float32) / 255, GRID.shape[::-1],
                               interpolation=cv2.INTER_AREA)
            cover = cv2.GaussianBlur(cover, (0, 0), 0.7)
            tree = measure_tree(cover > 0.5, GRID, SPACING, SPACING, TreeParams(), cover)
            error = tree.nodes[tree.tips] - tip
            error = error[np.argmin(np.hypot(*error.T))]
            errors.append(float(error @ np.subtract(tip, fork)) / 0.06)
    assert np.max(np.abs(errors)) < 0.0015 and np.mean(np.abs(errors)) < 0.0008, errors


def test_a_fork_has_two_tips_and_one_shared_node():
    tree = tree_of(mask_of([(0.1, 0.0), (0.1, 0.1), (0.05, 0.15)], [(0.1, 0.1), (0.15, 0.15)]))
    assert tree.plants == 1 and tree.tips.size == 2
    tips = tree.nodes[tree.tips]
    assert near(tips, (0.05, 0.15))
    assert near(tips, (0.15, 0.15))
    fork = [i for i in range(len(tree.parent)) if np.count_nonzero(tree.parent == i) == 2]
    assert len(fork) == 1 and tree.nodes[fork[0]] == pytest.approx((0.1, 0.1), abs=0.005)


def test_a_short_thick_nub_is_a_pruned_spur_not_a_tip():
    stem = mask_of([(0.1, 0.0), (0.1, 0.15)], width_m=0.02)
    stem |= mask_of([(0.1, 0.08), (0.118, 0.085)], width_m=0.014)  # sticks out 8 mm
    tree = thick_tree_of(stem)
    assert tree.tips.size == 1 and tree.tips_pruned >= 1
    assert thick_tree_of(stem, spur_m=0.0, spur_radii=0.0).tips.size == 2  # unpruned: a tip


def test_a_short_shoot_narrowing_to_its_end_is_a_tip_not_a_spur():
    stem = mask_of([(0.1, 0.0), (0.1, 0.15)], width_m=0.02)
    stem |= mask_of([(0.1, 0.08), (0.118, 0.085)], width_m=0.004)  # as long, but thin
    tree = thick_tree_of(stem)
    assert tree.tips.size == 2 and near(tree.nodes[tree.tips], (0.118, 0.085), 0.01)
    assert thick_tree_of(stem, spur_taper=0.0).tips.size == 1  # without the taper rule: a spur


def test_two_stems_are_two_plants_left_to_right():
    tree = tree_of(mask_of([(0.15, 0.0), (0.15, 0.12)],
                           [(0.04, 0.0), (0.04, 0.05), (0.06, 0.1)]))
    assert tree.plants == 2
    assert tree.nodes[0, 0] == pytest.approx(0.04, abs=0.003)  # plant 0 is the left one
    assert tree.nodes[1, 0] == pytest.approx(0.15, abs=0.003)
    tips = tree.nodes[tree.tips]
    assert sorted(tree.plant[tree.tips]) == [0, 1]
    assert near(tips, (0.06, 0.1))
    assert near(tips, (0.15, 0.12))


def test_a_plant_count_the_challenge_cannot_have_is_refused_naming_both_counts():
    tree = tree_of(mask_of([(0.15, 0.0), (0.15, 0.12)], [(0.04, 0.0), (0.04, 0.1)]))
    with pytest.raises(CameraError, match=r'2 stem base\(s\) in the photo, the control '
                       r'challenge has 1 plant\(s\)') as e:
        measured_state(tree, SimConfig(challenge='control'), None, Target(0.4 + 0.5j), 3)
    assert e.value.code == PLANTS


def two_plants(skeleton_px: tuple[int, int], stem_radius_m: tuple[float, float]) -> PlantTree:
    return PlantTree(nodes=np.array([[0.04, 0.0], [0.15, 0.0]]), parent=np.array([-1, -1]),
                     plant=np.array([0, 1], np.int16), tips=np.zeros(0, np.int64), plants=2,
                     tips_pruned=0, skeleton_px=skeleton_px, unattached_px=0,
                     stem_radius_m=stem_radius_m, piece=(1, 1))


def test_plants_whose_shares_follow_their_stems_pass_the_share_check():
    # Radii 5 and 3.5 mm: cubed, 0.74 and 0.26 of the two; skeleton shares 0.75 and 0.25.
    gap = PipelineParams().max_share_gap
    check_shares(two_plants((300, 100), (0.005, 0.0035)), gap)
    check_shares(two_plants((100, 300), (0.005, float('nan'))), gap)  # a plant below the band
    check_shares(replace(two_plants((100, 300), (0.005, 0.0035)), plants=1,
                         skeleton_px=(100,), stem_radius_m=(0.005,), piece=(1,)), gap)
    # Plants that do not touch cannot be shared out wrongly: their stems are not compared.
    check_shares(replace(two_plants((100, 300), (0.005, 0.0035)), piece=(1, 2)), gap)
    check_shares(two_plants((100, 300), (0.005, 0.0035)), max_gap=0.5)  # a rig's own gap


def test_plants_whose_shares_contradict_their_stems_are_refused_naming_both():
    # The thick stem holds a quarter of the skeleton, the thin one three quarters: one
    # plant's crown was handed to the other where they touch.
    with pytest.raises(CameraError, match=r'shares of the skeleton are 0\.25, 0\.75, their '
                       r'stems \(radii 5\.0, 3\.5 mm, cubed\) say 0\.74, 0\.26, more '
                       r'than max_share_gap = 0\.25 apart') as e:
        check_shares(two_plants((100, 300), (0.005, 0.0035)), PipelineParams().max_share_gap)
    assert e.value.code == PLANTS


def test_each_plants_stem_radius_is_read_above_the_floor():
    tree = tree_of(mask_of([(0.05, 0.0), (0.05, 0.17)], width_m=0.016)
                   | mask_of([(0.15, 0.0), (0.15, 0.17)], width_m=0.008))
    assert tree.stem_radius_m == pytest.approx((0.008, 0.004), abs=GRID.pixel_m)
    assert tree.piece[0] != tree.piece[1]  # apart
    joined = tree_of(mask_of([(0.05, 0.0), (0.05, 0.17)], [(0.15, 0.0), (0.15, 0.17)],
                             [(0.05, 0.12), (0.15, 0.12)]))
    assert joined.plants == 2 and joined.piece[0] == joined.piece[1]  # a branch joins them


def test_the_loops_of_a_mask_are_its_holes_and_a_net_of_them_is_refused():
    stem = mask_of([(0.1, 0.0), (0.1, 0.18)])
    assert tree_of(stem).loops == 0
    # Two twigs that leave the stem and join it again, one each side: two pieces of backdrop
    # enclosed.
    crossed = stem | mask_of([(0.1, 0.05), (0.16, 0.12), (0.1, 0.16)],
                             [(0.1, 0.07), (0.04, 0.12), (0.1, 0.15)], width_m=0.006)
    tree = tree_of(crossed)
    assert tree.loops == 2
    check_loops(tree, PipelineParams().max_loops)
    with pytest.raises(CameraError, match=r'the plant mask is a net of 2 loops '
                       r'\(max_loops = 1\)') as e:
        check_loops(tree, max_loops=1)
    assert e.value.code == UNEXPLAINED


@pytest.mark.parametrize('piece, refused', [
    ([(0.10, 0.18), (0.11, 0.19)], True),  # 1.2 cm wide, 5 cm over the stem's top
    ([(0.10, 0.14), (0.11, 0.15)], False),  # 1 cm over it: a leaf the mask cut off, near
    ([(0.19, 0.18), (0.19, 0.19)], False),  # beside, not over the plant (a cabinet's edge)
    ([(0.01, 0.18), (0.01, 0.19)], False),  # beside it on the other side
])
def test_plant_far_above_the_measured_plant_that_no_stem_reaches_is_refused(piece, refused):
    """A flower cluster over a stem the mask lost (the real bolting photo's dark racemes):
    the tree measured is the plant's lower part, its reward a confident wrong number."""
    stem = mask_of([(0.1, 0.0), (0.1, 0.12)])
    mask = stem | mask_of(piece)
    tree = tree_of(mask)
    assert tree.plants == 1 and tree.unexplained_px > 0
    if not refused:
        check_floating(mask, tree, GRID, max_float_m=0.03)
        return
    with pytest.raises(CameraError, match=r'plant 0\.05 m above the measured plants reaches '
                       r'no stem base \(max_float_m = 0\.03\)') as e:
        check_floating(mask, tree, GRID, max_float_m=0.03)
    assert e.value.code == UNEXPLAINED
    thin = stem | mask_of([(0.1, 0.17), (0.1, 0.19)], width_m=0.004)  # a line: an edge's
    check_floating(thin, tree_of(thin), GRID, max_float_m=0.03)
    check_floating(mask, tree, GRID, max_float_m=0.0)  # 0: off


def test_a_lines_width_and_a_neighbours_height_do_not_decide_the_floating_check():
    """At the camera's 2.5 mm pixels: a line 3 pixels (7.5 mm) wide over the plant, even along
    the chamber's top row, is an edge's line, not plant; and a cluster over a short plant is
    measured against that plant's top, not against a taller neighbour's."""
    grid = Grid(0.3, 0.3, 0.0025)

    def stems(*tops: tuple[float, float]) -> np.ndarray:
        return mask_of(*[[(x, 0.0), (x, z)] for x, z in tops], width_m=0.0125, grid=grid)

    def refused(mask: np.ndarray) -> bool:
        tree = measure_tree(mask, grid, SPACING, SPACING, TreeParams())
        try:
            check_floating(mask, tree, grid, max_float_m=0.03)
        except CameraError:
            return True
        return False

    column, first, last = int(0.15 / grid.pixel_m), grid.shape[0] - 104, grid.shape[0] - 80
    line = stems((0.15, 0.10))
    line[first:last, column - 1:column + 2] = True  # 3 pixels wide, z 0.20-0.26 m
    assert not refused(line)
    top_row = stems((0.15, 0.10))
    top_row[0:3, 40:80] = True  # along the chamber's top edge, x 0.10-0.20 m
    assert not refused(top_row)
    pair = stems((0.08, 0.28), (0.22, 0.10))  # a tall plant and a short one
    # 1.75 cm across, 7 cm over the short one and under the tall one's top
    assert refused(pair | mask_of([(0.22, 0.18)], width_m=0.0175, grid=grid))


def test_a_plant_measured_as_its_base_alone_is_refused_not_scored_zero():
    # Plant 0 is a root with nothing above it: scored, it would be no plant (reward 0).
    bare = PlantTree(nodes=np.array([[0.04, 0.0], [0.15, 0.0], [0.15, 0.05], [0.15, 0.1]]),
                     parent=np.array([-1, -1, 1, 2], np.int32),
                     plant=np.array([0, 1, 1, 1], np.int16), tips=np.array([3]), plants=2,
                     tips_pruned=0, skeleton_px=(0, 40), unattached_px=0)
    with pytest.raises(CameraError, match=r'plant\(s\) \[0\]: a stem base with nothing '
                       r'measured above it') as e:
        measured_state(bare, SimConfig(challenge='fairness'), None, Target(0.4 + 0.5j), 3)
    assert e.value.code == NO_PLANT


def test_crossing_branches_still_make_a_tree_of_one_plant():
    tree = tree_of(mask_of([(0.1, 0.0), (0.1, 0.06), (0.04, 0.16)],
                           [(0.1, 0.06), (0.16, 0.1), (0.06, 0.12)]))
    assert tree.plants == 1
    assert np.all(tree.parent[1:] < np.arange(1, len(tree.parent)))
    assert near(tree.nodes[tree.tips], (0.04, 0.16))


def test_a_loose_piece_of_plant_is_counted_not_attached():
    mask = mask_of([(0.1, 0.0), (0.1, 0.1)]) | mask_of([(0.03, 0.15), (0.07, 0.17)])
    tree = tree_of(mask)
    assert tree.plants == 1 and tree.unattached_px > 10
    loose = mask_of([(0.03, 0.15), (0.07, 0.17)])
    assert tree.unexplained_px == np.count_nonzero(loose)  # its mask pixels, for the gate
    assert not near(tree.nodes, (0.05, 0.16), 0.02)


@pytest.mark.parametrize('mask, match', [
    (np.zeros(GRID.shape, bool), 'the mask is empty'),
    (mask_of([(0.05, 0.1), (0.15, 0.12)]), 'no stem reaches the floor'),
])
def test_no_plant_is_an_error_not_an_empty_answer(mask, match):
    with pytest.raises(CameraError, match=match) as e:
        tree_of(mask)
    assert e.value.code == NO_PLANT


@pytest.mark.parametrize('width_m', [0.008, 0.012, 0.02])
def test_a_round_tip_is_the_centre_of_its_end_not_the_masks_edge(width_m):
    # The node a branch ends at is the centre of its round end; the mask reaches half the
    # stem's width beyond it (4 to 10 mm here).
    measure = thick_tree_of if width_m >= 0.02 else tree_of
    tree = measure(mask_of([(0.1, 0.0), (0.1, 0.1), (0.16, 0.13)], width_m=width_m))
    assert tree.tips.size == 1
    assert np.hypot(*(tree.nodes[tree.tips[0]] - (0.16, 0.13))) < 0.0025


def test_a_stem_an_even_number_of_pixels_wide_is_measured_on_its_axis():
    # Thinning keeps one of the two middle columns (half a pixel, 1 mm, off the axis); the
    # nodes must lie on the axis itself, here on a pixel border at x = 0.1 m.
    mask = np.zeros(GRID.shape, bool)
    mask[20:, 47:53] = True  # 6 pixels wide: columns 47-52, axis between 49 and 50
    tree = tree_of(mask)
    assert tree.plants == 1 and len(tree.nodes) >= 4
    assert np.abs(tree.nodes[:, 0] - 0.1).max() < 0.0003


# --- stem bases, leaves on the floor, the stem's cut end -------------------------------------

STEM = [(0.1, 0.0), (0.1, 0.17)]
# Two leaves on petioles at 8 and 10 cm that arch out and droop across the soil line (drawn on
# below the floor, as a leaf hangs over the pot's rim): the lower 7 cm of each is steep, 10 and
# 9 degrees off vertical, and as wide as a blade (8 mm against the stem's 12).
LEFT_LEAF = [(0.1, 0.08), (0.06, 0.10), (0.03, 0.07), (0.015, -0.02)]
RIGHT_LEAF = [(0.1, 0.10), (0.14, 0.12), (0.17, 0.08), (0.185, -0.02)]


def test_leaves_drooping_across_the_soil_line_are_leaves_of_one_plant_not_plants():
    mask = mask_of(STEM) | mask_of(LEFT_LEAF, RIGHT_LEAF, width_m=0.008)
    tree = tree_of(mask)
    assert tree.plants == 1
    assert tree.nodes[0] == pytest.approx((0.1, 0.0), abs=0.003)  # the stem's base
    tips = tree.nodes[tree.tips]
    assert near(tips, (0.1, 0.17))  # the shoot
    assert set(tree.plant) == {0}
    assert tree.unexplained_px == 0


def test_a_leaf_meeting_the_floor_at_a_slant_is_not_a_stem_base():
    mask = mask_of(STEM) | mask_of([(0.1, 0.09), (0.05, 0.1), (0.01, 0.0)], width_m=0.01)
    tree = tree_of(mask)
    assert tree.plants == 1 and tree.nodes[0] == pytest.approx((0.1, 0.0), abs=0.003)


def test_a_twig_lying_across_the_soil_line_is_not_a_stem():
    # A loose twig (a tip of its own: only its slant, 51 degrees off vertical, tells it from a
    # second plant) is plant no stem base explains.
    stem = mask_of([(0.18, 0.0), (0.18, 0.17)])
    twig = mask_of([(0.0, -0.01), (0.15, 0.11)], width_m=0.008)
    tree = tree_of(stem | twig)
    assert tree.plants == 1 and tree.nodes[0] == pytest.approx((0.18, 0.0), abs=0.003)
    assert tree.unexplained_px == np.count_nonzero(twig & ~stem)
    assert tree_of(stem | twig, max_base_tilt_deg=90.0).plants == 2  # the slant did it


def test_two_stems_with_a_leaf_each_on_the_floor_are_two_plants():
    mask = mask_of([(0.05, 0.0), (0.05, 0.17)], [(0.15, 0.0), (0.15, 0.17)]) \
        | mask_of([(0.05, 0.08), (0.08, 0.09), (0.095, -0.02)],
                  [(0.15, 0.09), (0.18, 0.1), (0.195, -0.02)], width_m=0.006)
    tree = tree_of(mask)
    assert tree.plants == 2
    assert tree.nodes[:2, 0] == pytest.approx((0.05, 0.15), abs=0.003)


@pytest.mark.parametrize('width_px', [9, 12, 16, 20])
@pytest.mark.parametrize('cut_px', [0, 2])
def test_a_stems_square_cut_end_has_no_tips_at_its_corners(width_px, cut_px):
    # A stem cut square at (or just above) the floor, leaning 0 to 8 px over its 15 cm as a
    # photographed stem does: thinning runs a short branch into a corner of the cut end,
    # thinner at its end than the stem, as a shoot is (before: 38 of these 72 had a tip at the
    # base; on the twin's photos, 14 of 683 tips sat within 2 cm of the floor).
    for lean_px in range(9):
        mask = np.zeros(GRID.shape, np.uint8)
        left, bottom = 50 - width_px // 2, 99 - cut_px
        right = left + width_px - 1
        cv2.fillConvexPoly(mask, np.array([[left, bottom], [right, bottom], [right - lean_px, 25],
                                           [left - lean_px, 25]], np.int32), 1)
        tree = thick_tree_of(mask.astype(bool))
        tips = tree.nodes[tree.tips]
        assert tree.plants == 1 and len(tips) == 1 and tips[0][1] > 0.12, (lean_px, tips)
