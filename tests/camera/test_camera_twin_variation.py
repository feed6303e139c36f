"""The photo twin's variations (how rigs differ) and the segmentation that must hold on them:
hard lamp edges, brown woody stems, textured backdrops. Files and arrays only."""

from __future__ import annotations


import cv2
import numpy as np
import pytest

from growspace_camera.markers import MarkerLayout
from growspace_camera.measure import Target
from growspace_camera.pipeline import Pipeline
from growspace_camera.segment import plant_mask, SegmentParams
from growspace_camera.twin import FACTORS, HELD_OUT_FIRST, PhotoTwin, Variation
from test_camera_vision import grown_by_oracle

LAYOUT = MarkerLayout()


@pytest.fixture(scope='module')
def chamber():
    """A fairness chamber (two plants) grown 24 steps by its oracle."""
    return grown_by_oracle('fairness', 'hard', seed=5, steps=24)


def test_a_factor_changes_its_own_draws_only(chamber):
    twin = PhotoTwin(LAYOUT, size=(640, 360))
    old = twin.photo(chamber.sim.chamber, seed=8)
    assert twin.photo(chamber.sim.chamber, seed=8, variation=Variation()).jpeg == old.jpeg
    woody = twin.photo(chamber.sim.chamber, seed=8, variation=Variation.only('woody'))
    # Same pose, light, exposure, blur and noise; only the stems' colour differs.
    assert woody.conditions == old.conditions and woody.jpeg != old.jpeg
    again = twin.photo(chamber.sim.chamber, seed=8, variation=Variation.only('woody'))
    assert again.jpeg == woody.jpeg


def test_every_factor_draws_a_photo(chamber):
    twin = PhotoTwin(LAYOUT, size=(320, 180))
    for name in FACTORS:
        shot = twin.photo(chamber.sim.chamber, seed=3, variation=Variation.only(name))
        assert shot.bgr.shape == (180, 320, 3), name
    assert twin.photo(chamber.sim.chamber, seed=3, variation=Variation.every()).bgr.size


def test_an_unknown_factor_is_named():
    with pytest.raises(ValueError, match=r"unknown factor\(s\) \['glare'\]"):
        Variation(frozenset({'woody', 'glare'}))


def test_combinations_are_seeded_and_never_empty():
    ids = list(range(50)) + [HELD_OUT_FIRST + k for k in range(50)]
    assert all(Variation.combination(k) == Variation.combination(k) for k in ids)
    assert all(Variation.combination(k).factors for k in ids)
    assert len({Variation.combination(k).factors for k in ids}) > 40


GREEN_SHOOT = (60.0, 140.0, 70.0)


def grey(size: int = 160, level: float = 150.0) -> np.ndarray:
    return np.full((size, size, 3), level, np.float32)


@pytest.mark.parametrize('cast', [(0.85, 0.3, 1.0), (1.0, 0.35, 0.25), (0.15, 0.1, 1.0)])
def test_a_hard_lamp_edge_is_not_plant(cast):
    # A rectified chamber without plant, the grow lamp's cast cut off sharply (an LED bar)
    # at a third of its width: a mean over a window across the edge would colour a line.
    photo = grey()
    photo[:, 53:] *= 1.0 + 0.5 * np.array(cast, np.float32)
    photo = cv2.GaussianBlur(photo, (0, 0), 0.7)
    photo += np.random.default_rng(1).normal(0.0, 2.0, photo.shape).astype(np.float32)
    seg = plant_mask(photo, SegmentParams())
    assert not seg.mask.any(), np.argwhere(seg.mask)[:5]


def test_a_hard_lamp_edge_beside_a_stem_leaves_only_the_stem():
    photo = grey()
    photo[:, 90:95] = (60.0, 140.0, 70.0)  # a green stem
    photo[:, 53:] *= np.array((1.42, 1.15, 1.5), np.float32)  # magenta beyond the edge
    seg = plant_mask(cv2.GaussianBlur(photo, (0, 0), 0.7), SegmentParams())
    columns = np.flatnonzero(seg.mask.any(axis=0))
    assert columns.min() >= 88 and columns.max() <= 96, columns


@pytest.mark.parametrize('gap', [3, 6, 12])
def test_the_unlit_backdrop_between_lamp_bands_is_not_plant(gap):
    # An LED bar's beam in four hard-edged bands with unlit backdrop between them, narrower
    # than half the flat field's window: the light estimated there keeps the lamp's magenta,
    # and the grey backdrop read green after the division, a stem from the floor to the top.
    photo = grey()
    pitch = 14 + gap
    for k in range(4):
        left = 40 + k * pitch
        photo[:, left:left + 14] *= np.array((1.42, 1.15, 1.5), np.float32)
    photo[:, 100:104] = GREEN_SHOOT  # a full-height stem in the unlit strip right of the beam
    photo[60:64, 30:104] = GREEN_SHOOT  # a branch across every band and gap
    seg = plant_mask(cv2.GaussianBlur(photo, (0, 0), 0.7), SegmentParams())
    stray = seg.mask.copy()  # what is plant beyond the plant and the blur and halo beside it
    stray[:, 96:108] = False
    stray[54:70] = False
    assert not stray.any(), np.unique(np.argwhere(stray)[:, 1])
    assert seg.mask[:, 100:104].all() and seg.mask[61, 30:104].all()


@pytest.mark.parametrize('bark', [(50.0, 76.0, 99.0), (38.0, 47.0, 60.0), (70.0, 95.0, 125.0)])
def test_a_brown_woody_stem_is_plant_a_neutral_dark_line_is_not(bark):
    photo = grey(level=170.0)
    photo[:, 40:48] = bark  # the woody stem, not greener than the backdrop
    photo[:20, 42:46] = GREEN_SHOOT  # ... which carries a green shoot
    photo[:, 110:113] = 125.0  # a neutral dark line (wood grain, a fold)
    seg = plant_mask(cv2.GaussianBlur(photo, (0, 0), 0.7), SegmentParams())
    assert seg.mask[20:140, 40:48].all()
    columns = np.flatnonzero(seg.mask[20:140].any(axis=0))
    assert columns.min() >= 38 and columns.max() <= 50, columns


@pytest.mark.parametrize('bark', [(38.0, 47.0, 60.0), (24.0, 43.0, 64.0)])
def test_a_wide_brown_trunk_is_plant_down_to_the_floor(bark):
    # A woody trunk tapering from 8 cm at the floor (wider than half the first flat field's
    # 12 cm window, which took it for light and divided it away: the plant floated) to 2.5 cm
    # where its green shoot goes on.
    photo = grey(level=150.0)
    for row in range(40, 160):
        half = int(round(5 + 11 * (row - 40) / 120))
        photo[row, 80 - half:80 + half] = bark
    photo[:40, 76:84] = GREEN_SHOOT
    seg = plant_mask(cv2.GaussianBlur(photo, (0, 0), 0.7), SegmentParams())
    assert seg.mask[150:158, 68:92].all(), np.count_nonzero(seg.mask[150:158, 68:92])
    assert not seg.mask[:, :55].any() and not seg.mask[:, 105:].any()


@pytest.mark.parametrize('post, width', [((8.0, 16.0, 24.0), 6), ((40.0, 60.0, 85.0), 6),
                                         ((7.0, 10.0, 6.0), 30)])
def test_a_dark_cabinet_post_is_not_plant_even_if_warm_or_tinted(post, width):
    # As on the real photos: a dark post with a warm tint, or a black one with a green tint
    # (sensor, JPEG) wider than the flat field's window, down to the floor. Brown counts only
    # on a green shoot, and a black pixel has no colour to read.
    photo = grey(level=190.0)
    photo[:, 120:120 + width] = post
    photo[:, 60:64] = GREEN_SHOOT
    seg = plant_mask(cv2.GaussianBlur(photo, (0, 0), 0.7), SegmentParams())
    assert not seg.mask[:, 100:].any(), np.argwhere(seg.mask[:, 100:])[:5]
    assert seg.mask[:, 60:64].all()


def test_the_soil_line_is_not_a_stem():
    photo = grey()
    photo[-2:] = (40.0, 50.0, 70.0)  # soil blurred into the chamber's bottom rows
    photo[:, 70:76] = (50.0, 76.0, 99.0)  # a woody stem down to the floor
    photo[:20, 71:75] = GREEN_SHOOT
    seg = plant_mask(cv2.GaussianBlur(photo, (0, 0), 0.7), SegmentParams())
    assert not seg.mask[-2:, :60].any() and seg.mask[-1, 70:76].any()


def test_a_woody_plant_under_a_hard_edged_lamp_is_measured(chamber):
    c = chamber.sim.chamber
    variation = Variation(frozenset({'woody', 'lamp_edge'}))
    shot = PhotoTwin(LAYOUT).photo(c, seed=21, variation=variation)
    m = Pipeline().measure(shot.bgr, chamber.cfg, c.light.copy(), Target(c.target), c.steps)
    assert m.ok, m.error
    assert abs(m.reward - chamber.reward) < 0.05


def test_a_rigs_camera_stays_put_through_an_episode(chamber):
    twin, c = PhotoTwin(LAYOUT, size=(320, 180)), chamber.sim.chamber
    camera = Variation.only('camera')
    a = twin.photo(c, seed=101, variation=camera, rig_seed=7)
    b = twin.photo(c, seed=102, variation=camera, rig_seed=7)
    assert np.array_equal(a.pose.centre, b.pose.centre) and a.jpeg != b.jpeg
    apart = twin.photo(c, seed=102, variation=camera)
    assert not np.array_equal(apart.pose.centre, a.pose.centre)
    # The default twin keeps its photo-by-photo pose (its figures do not move).
    assert twin.photo(c, seed=102, rig_seed=7).jpeg == twin.photo(c, seed=102).jpeg
