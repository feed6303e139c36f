"""The camera pipeline on real plant photos it was never tuned to (issue 30, item 5).

The photos (tests/data/real_photos: public PlantCV images, MPL-2.0, see MANIFEST.yaml) carry the
project's ArUco markers at the margins (``scripts/real_photos.py`` rebuilds them from their
sources). The expectations were checked by hand, by eye on enlarged crops of each photo with a
1 cm chamber grid: points of plant (stem, leaves, a brown trunk) that must be in the mask,
points of backdrop, cabinet and pot that must not be, where tips must be, and what must be
refused. They say what a phenotyping lab would accept, not what today's pipeline does: the
ones it fails are marked ``xfail(strict=True)`` with the issue item that fixes them, so a fix
shows up as an unexpected pass to flip.

All points are chamber (x, z) [m]: x along the rail, z up from the soil line (the pot's front
rim). Files only: no device, no network.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import functools
import hashlib
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from growspace_camera.errors import BAD_INPUT, EXPOSURE, FIT, MARKERS, NO_PHOTO, UNEXPLAINED
from growspace_camera.measure import Target
from growspace_camera.pipeline import Measurement, Pipeline
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import Light

HERE = Path(__file__).resolve().parents[1] / 'data' / 'real_photos'
CFG = SimConfig(challenge='control')  # one plant, a point target
LIGHT = Light(False, 0.42, 0.84, 0.2, 0.1)  # a 20 cm beam over the plant
TARGET = Target(0.42 + 0.6j)
NEAR_PX = 1  # a point is in the mask when a pixel within this many grid pixels is (2.5 mm)
TIP_M = 0.02  # a measured tip within this of each expected tip end
FOOT_M = 0.015  # no tip this near the stem's foot on the soil line (the cut base)
ACCEPT_WITHIN = 0.05  # a measured reward this near the truth (the bench's accept_precision)
# Reasons that say the photo could not be read at all: a refused plant photo must name the
# plant instead (no_plant, plants, or a quality gate on the measured tree).
PHOTO_REASONS = (NO_PHOTO, EXPOSURE, MARKERS, FIT, BAD_INPUT)
ITEM2 = 'issue 30 item 2 (segmentation: v-twin)'
ITEM3 = 'issue 30 item 3 (plants, stems and leaves: v-gates)'
ITEM4 = 'issue 30 item 4 (quality gates: v-gates)'


@dataclass(frozen=True)
class Expected:
    """What a photo must give.

    Attributes:
        plant: Named groups of points that must be in the mask.
        not_plant: Named groups of points that must not be.
        accepted: The photo must be measured (one plant); False: refused, naming the plant.
        tips: Named groups of shoot and leaf ends: a measured tip within ``TIP_M`` of each.
        foot: Where the stem meets the soil line: no tip within ``FOOT_M`` of it.
        reward: The challenge's reward read off the photo by hand (``TARGET``), where it is
            clear: a measured photo must give it within ``ACCEPT_WITHIN``, or be refused.
    """

    plant: dict[str, tuple[tuple[float, float], ...]] = field(default_factory=dict)
    not_plant: dict[str, tuple[tuple[float, float], ...]] = field(default_factory=dict)
    accepted: bool = True
    tips: dict[str, tuple[tuple[float, float], ...]] = field(default_factory=dict)
    foot: tuple[float, float] | None = None
    reward: float | None = None


EXPECTED = {
    # Stem and every leaf, two lower leaves drooping over the pot rim (the right one far
    # below the soil line): one plant.
    'leafy_side_view': Expected(
        plant={'leaves': ((0.359, 0.221), (0.369, 0.136), (0.474, 0.116), (0.434, 0.176),
                          (0.446, 0.034)),
               'stem': ((0.411, 0.041), (0.411, 0.104), (0.411, 0.196), (0.409, 0.301),
                        (0.409, 0.384), (0.404, 0.436)),
               # where they cross the pot rim: not to be cut off to make one stem base
               'leaves drooping over the rim': ((0.299, 0.011), (0.504, 0.002))},
        not_plant={'backdrop': ((0.33, 0.38), (0.47, 0.30), (0.36, 0.175), (0.60, 0.60),
                                (0.20, 0.10)),
                   'cabinet posts': ((0.01, 0.40), (0.83, 0.40)),
                   'soil in the pot': ((0.446, 0.004),)},
        tips={'shoot and leaf ends': ((0.395, 0.45), (0.33, 0.22), (0.49, 0.19), (0.52, 0.13),
                                      (0.33, 0.125), (0.36, 0.32))},
        foot=(0.41, 0.0)),
    # A seedling: a shoot and four leaves, their ends two source pixels wide and pale.
    'seedling_thin_leaves': Expected(
        plant={'shoot and leaves': ((0.414, 0.006), (0.416, 0.179), (0.434, 0.114)),
               'thin leaves': ((0.361, 0.139), (0.341, 0.144), (0.361, 0.054))},
        not_plant={'backdrop': ((0.355, 0.195), (0.485, 0.078), (0.394, 0.234), (0.654, 0.52)),
                   'cabinet post edge': ((0.800, 0.643), (0.799, 0.309)),
                   'pot and soil': ((0.472, 0.003),)},
        # The two left leaf ends as their last source pixels with any green (raw 2g - r - b of
        # 5 or more of 255, read on the source at 4x, 2026-11-29); until then they stood 1.3
        # and 2.6 cm beyond them, on backdrop.
        tips={'shoot and the right leaf': ((0.436, 0.267), (0.466, 0.159)),
              'thin left leaf ends': ((0.319, 0.143), (0.352, 0.052))},
        foot=(0.417, 0.0)),
    # Thin grass leaves arching out and down past the pot on both sides: one plant.
    'grass_drooping_leaves': Expected(
        plant={'shoot and leaves': ((0.396, 0.209), (0.404, 0.106), (0.301, 0.146),
                                    (0.331, 0.096), (0.526, 0.044)),
               'leaves drooping over the rim': ((0.301, 0.026), (0.566, 0.026))},
        not_plant={'backdrop': ((0.342, 0.208), (0.524, 0.156), (0.524, 0.104), (0.654, 0.52)),
                   'cabinet post edge': ((0.815, 0.304), (0.813, 0.21))},
        tips={'shoot': ((0.407, 0.254),)},
        foot=(0.42, 0.0)),
    # A small tree: a brown, woody, leaning trunk (tissue excess green does not see), green
    # leaves above; a blue mesh on the soil.
    'woody_tree': Expected(
        plant={'leaves': ((0.294, 0.261), (0.314, 0.441), (0.364, 0.294)),
               'brown trunk': ((0.404, 0.041), (0.384, 0.081), (0.361, 0.119),
                               (0.344, 0.139))},
        not_plant={'backdrop': ((0.425, 0.10), (0.50, 0.30), (0.25, 0.05), (0.60, 0.60)),
                   'mesh on the soil': ((0.47, 0.008),)},
        tips={'crown': ((0.325, 0.47),)},
        foot=(0.418, 0.012)),
    # A leafy dicot in a tall black pot: narrow leaves up a single stem to its apex, the lower
    # ones arching out over the rim and hanging below the soil line on both sides, in front
    # of the pot (black behind them there): one plant. The leaves' ends, read on the photo at
    # 4x and 8x with a 1 cm grid (2026-11-29); three of them taper into pale tails.
    'leafy_dicot_dark_pot': Expected(
        plant={'stem': ((0.42, 0.03), (0.42, 0.12), (0.42, 0.20), (0.418, 0.28)),
               'leaves': ((0.36, 0.072), (0.47, 0.11), (0.44, 0.235), (0.38, 0.20)),
               'leaves drooping over the rim': ((0.309, 0.01), (0.532, 0.01))},
        not_plant={'backdrop': ((0.30, 0.12), (0.47, 0.07), (0.55, 0.05), (0.38, 0.31),
                                (0.50, 0.28), (0.60, 0.60)),
                   'cabinet posts': ((0.01, 0.40), (0.83, 0.40))},
        tips={'apex and leaf ends': ((0.417, 0.324), (0.448, 0.314), (0.459, 0.289),
                                     (0.372, 0.267), (0.475, 0.261), (0.517, 0.211),
                                     (0.489, 0.139), (0.331, 0.080), (0.336, 0.150)),
              'pale leaf tails': ((0.338, 0.221), (0.500, 0.171), (0.542, 0.100))},
        foot=(0.42, 0.0)),
    # A bolting plant, 0.70 m: a tall flowering stem and thin side racemes, dark grey-green
    # above the rosette, with small yellow-green flower clusters; narrow leaves up the stem;
    # yellowing leaves droop over the pot. Read on the photo at 4x with a 1 cm grid
    # (2026-11-29). A side raceme passes 1.2 cm from the target (0.42, 0.60), inside its 2.5 cm
    # disc: the reward is 1.
    'bolting_with_yellow_leaves': Expected(
        plant={'rosette and lower stem': ((0.40, 0.10), (0.40, 0.20), (0.399, 0.27)),
               'yellowing leaves': ((0.50, 0.032), (0.328, 0.056)),
               'dark stems above': ((0.394, 0.35), (0.393, 0.40), (0.388, 0.45),
                                    (0.384, 0.60), (0.383, 0.65), (0.42, 0.612)),
               'flower clusters': ((0.466, 0.552), (0.477, 0.618))},
        not_plant={'backdrop': ((0.45, 0.45), (0.33, 0.42), (0.55, 0.55), (0.42, 0.66),
                                (0.60, 0.30)),
                   'cabinet posts': ((0.11, 0.40), (0.74, 0.40))},
        tips={'raceme ends': ((0.484, 0.466), (0.477, 0.628), (0.466, 0.56))},
        foot=(0.42, 0.0), reward=1.0),
    # Not side views of a plant on the soil line: the camera must refuse them.
    'top_view': Expected(accepted=False),
    'trays_top_view': Expected(accepted=False),
}
XFAIL = {  # (photo, test, group) -> why today's pipeline fails it (checked 2026-11-29)
    ('seedling_thin_leaves', 'plant', 'thin leaves'):
        f'{ITEM2}: thin, pale leaf blades and their ends fall below the threshold',
    ('seedling_thin_leaves', 'tips', 'thin left leaf ends'):
        f'{ITEM2} and {ITEM3}: accepted (reward 0.073; {ITEM4}) with the ends of both '
        'thin left leaves lost (no tip within 6 cm of them)',
    ('bolting_with_yellow_leaves', 'plant', 'dark stems above'):
        f'{ITEM2}: dark grey-green stems on a white backdrop have no excess green (the mask '
        'stops 0.35 m up the 0.70 m stem)',
    ('bolting_with_yellow_leaves', 'outcome', ''):
        f'{ITEM2}: refused, rightly for now (unexplained: its flower clusters, 0.26 m over '
        "the mask's top, reach no stem base; accepted, its reward was 0.085 for 1)",
    ('bolting_with_yellow_leaves', 'tips', 'raceme ends'): f'{ITEM2}: refused (as above)',
    ('bolting_with_yellow_leaves', 'foot', ''): f'{ITEM2}: refused (as above)',
    ('leafy_dicot_dark_pot', 'tips', 'pale leaf tails'):
        f'{ITEM2}: the pale tails of three narrow leaves fall below the threshold (no tip '
        'within 2.4-3.6 cm of their ends)',
}


def xfail(photo: str, test: str, group: str = '') -> list:
    reason = XFAIL.get((photo, test, group))
    return [pytest.mark.xfail(strict=True, reason=reason)] if reason else []


@functools.cache
def measured(photo: str) -> Measurement:
    """The pipeline's measurement of a stored photo (once per test run)."""
    bgr = cv2.imread(str(HERE / f'{photo}.jpg'), cv2.IMREAD_COLOR)
    assert bgr is not None, f'{photo}.jpg cannot be read'
    return Pipeline().measure(bgr, CFG, LIGHT, TARGET)


def mask_near(m: Measurement, points: tuple[tuple[float, float], ...]) -> list[bool]:
    """Per chamber point, whether the mask has plant within ``NEAR_PX`` grid pixels of it."""
    grid, mask = m.grid, m.segmentation.mask
    rows, cols = grid.shape
    found = []
    for x, z in points:
        r = int(rows - z / grid.pixel_m)
        c = int(x / grid.pixel_m)
        window = mask[max(0, r - NEAR_PX):r + NEAR_PX + 1, max(0, c - NEAR_PX):c + NEAR_PX + 1]
        found.append(bool(window.any()))
    return found


def cases(kind: str) -> list:
    return [pytest.param(photo, group, marks=xfail(photo, kind, group),
                         id=f'{photo}-{group.replace(" ", "_")}')
            for photo, e in EXPECTED.items() for group in getattr(e, kind)]


# --- the stored files ------------------------------------------------------------------------

def test_every_photo_is_in_the_manifest_with_its_source_licence_and_checksum():
    manifest = yaml.safe_load((HERE / 'MANIFEST.yaml').read_text(encoding='utf-8'))
    source = manifest['source']
    assert source['licence'] == 'MPL-2.0' and len(source['commit']) == 40
    licence = (HERE / source['licence_file']).read_text(encoding='utf-8')
    assert licence.startswith('Mozilla Public License Version 2.0')
    entries = {e['name']: e for e in manifest['photos']}
    assert set(entries) == set(EXPECTED)
    total = 0
    for name, entry in entries.items():
        data = (HERE / entry['file']).read_bytes()
        total += len(data)
        assert hashlib.sha256(data).hexdigest() == entry['built_sha256'], name
        assert len(data) <= 150_000, name
        assert len(entry['sha256']) == 64 and entry['path'] and entry['shows'], name
    assert total < 1_000_000


@pytest.mark.parametrize('photo', list(EXPECTED))
def test_all_four_markers_are_found_and_the_plane_fits(photo):
    m = measured(photo)
    assert m.confidence.markers_seen == (0, 1, 2, 3), m.error
    assert m.fit is not None and m.fit.check_error_m < 0.002
    assert m.segmentation is not None, m.error


# --- the mask --------------------------------------------------------------------------------

@pytest.mark.parametrize('photo, group', cases('plant'))
def test_plant_points_are_in_the_mask(photo, group):
    m = measured(photo)
    points = EXPECTED[photo].plant[group]
    missing = [p for p, hit in zip(points, mask_near(m, points)) if not hit]
    assert not missing, f'{group} not in the mask at {missing}'


@pytest.mark.parametrize('photo, group', cases('not_plant'))
def test_backdrop_cabinet_and_pot_are_not_in_the_mask(photo, group):
    m = measured(photo)
    points = EXPECTED[photo].not_plant[group]
    wrong = [p for p, hit in zip(points, mask_near(m, points)) if hit]
    assert not wrong, f'{group} in the mask at {wrong}'


# --- what the photo gives --------------------------------------------------------------------

@pytest.mark.parametrize('photo', [pytest.param(p, marks=xfail(p, 'outcome'))
                                   for p in EXPECTED])
def test_a_plant_photo_is_measured_and_anything_else_refused_naming_the_plant(photo):
    m, e = measured(photo), EXPECTED[photo]
    if e.accepted:
        assert m.ok, m.error
        assert m.tree.plants == 1
    else:
        assert not m.ok, f'accepted with reward {m.reward:.3f}'
        assert m.error.code not in PHOTO_REASONS, m.error
        assert m.reward == 0.0 and m.state is None


@pytest.mark.parametrize('photo', [pytest.param(p, marks=xfail(p, 'reward'))
                                   for p, e in EXPECTED.items() if e.reward is not None])
def test_a_measured_reward_is_the_one_read_off_the_photo_or_the_photo_is_refused(photo):
    m, truth = measured(photo), EXPECTED[photo].reward
    assert not m.ok or abs(m.reward - truth) <= ACCEPT_WITHIN, \
        f'accepted with reward {m.reward:.3f}; read off the photo: {truth}'


def test_plant_over_a_stem_the_mask_missed_refuses_the_photo():
    """The bolting plant's flower clusters, over dark racemes the mask misses, reach no stem
    base: measured, the tree is its lower half (reward 0.085 for 1); refused, it says why."""
    m = measured('bolting_with_yellow_leaves')
    assert not m.ok and m.error.code == UNEXPLAINED
    assert 'm above the measured plants reaches no stem base (max_float_m = 0.05)' in str(m.error)


def _tips(m: Measurement) -> np.ndarray:
    assert m.ok, m.error
    return np.vstack((m.tree.nodes[m.tree.tips], m.tree.leaf_tips))  # shoots' and leaves'


@pytest.mark.parametrize('photo, group', cases('tips'))
def test_tips_are_at_shoot_and_leaf_ends(photo, group):
    seen = _tips(measured(photo))
    missed = [t for t in EXPECTED[photo].tips[group] if np.hypot(*(seen - t).T).min() > TIP_M]
    assert not missed, f'no tip within {TIP_M} m of {missed}; tips {np.round(seen, 3)}'


@pytest.mark.parametrize('photo', [pytest.param(p, marks=xfail(p, 'foot'))
                                   for p, e in EXPECTED.items() if e.accepted])
def test_no_tip_at_the_stems_cut_base(photo):
    seen = _tips(measured(photo))
    at_foot = seen[np.hypot(*(seen - EXPECTED[photo].foot).T) < FOOT_M]
    assert not len(at_foot), f'tips at the cut base: {np.round(at_foot, 3)}'
