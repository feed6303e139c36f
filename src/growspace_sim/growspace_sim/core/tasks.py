"""The four GrowSpace challenges: where plants, target and light start, and the rewards.

Layouts follow the paper (section 'Tasks') and MISSION.md's table. Every random draw goes through
the episode's ``np.random.Generator``, in a fixed order, so an episode is a function of its seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from growspace_sim.core.config import SimConfig

WALL_MARGIN = 0.05  # fraction of the width kept free between a stem and a wall


@dataclass(frozen=True)
class Layout:
    """The procedurally generated start of an episode, in metres."""

    stem_x: tuple[float, ...]  # m, one root per plant on the floor
    target: complex | None  # m, x + iz; None for the shape challenge
    light_x: float  # m, initial light centre
    light_z: float  # m, initial spotlight centre height


def draw_layout(cfg: SimConfig, rng: np.random.Generator) -> Layout:
    """Draw the stems, target and light start of one episode."""
    w, h = cfg.chamber_width, cfg.chamber_height
    lo, hi = WALL_MARGIN * w, (1.0 - WALL_MARGIN) * w
    top_quarter_z = float(rng.uniform(0.75 * h, h))  # 'target in the upper 25%'
    if cfg.challenge == 'shape':
        stem = 0.5 * w  # MNIST digits are centred in their 28 x 28 frame
        tip_z = cfg.width_m(cfg.first_branch_height)
        return Layout((stem,), None, stem, tip_z + cfg.width_m(cfg.spot_radius))
    if cfg.challenge == 'fairness':
        stems, target_x = _fairness_stems(cfg, rng, lo, hi)
    elif cfg.setting == 'easy':  # target above the stem
        stem = float(rng.uniform(0.1 * w, 0.9 * w))
        stems, target_x = (stem,), stem + float(rng.uniform(-0.05, 0.05)) * w
    else:  # stem and target at opposite sides
        near, far = float(rng.uniform(lo, 0.2 * w)), float(rng.uniform(0.8 * w, hi))
        if rng.integers(2):
            near, far = w - near, w - far
        stems, target_x = (near,), far
    if cfg.challenge == 'control':
        light_x = stems[0]  # the light starts above the stem
    else:  # find_plant and fairness: the light starts anywhere
        light_x = float(rng.uniform(0.0, w))
    return Layout(stems, complex(target_x, top_quarter_z), light_x, 0.0)


def _fairness_stems(cfg: SimConfig, rng: np.random.Generator, lo: float,
                    hi: float) -> tuple[tuple[float, ...], float]:
    w, n = cfg.chamber_width, cfg.plant_count
    if cfg.setting == 'easy':  # neighbours one light width apart, target in their middle
        gap = cfg.width_m(cfg.light_width)
        span = gap * (n - 1)
        centre = float(rng.uniform(lo + 0.5 * span, hi - 0.5 * span))
        stems = tuple(centre + (i - 0.5 * (n - 1)) * gap for i in range(n))
        return stems, centre
    # hard: the outer plants at opposite walls, any others spread between, target mid-chamber
    anchors = np.linspace(0.2 * w, 0.8 * w, n)
    jitter = rng.uniform(-0.05 * w, 0.05 * w, n)
    stems = tuple(float(x) for x in np.clip(anchors + jitter, lo, hi))
    return stems, 0.5 * w + float(rng.uniform(-0.05, 0.05)) * w


def distance_reward(distance: np.ndarray | float, unit: float) -> np.ndarray | float:
    """The paper's eq. 4 term ``1/d`` for one plant, with d measured in target radii.

    ``d`` is the Euclidean distance (m) from the plant's nearest node to the target centre,
    divided by the target radius ``unit`` (m) and floored at 1: a node inside the target disc
    has reached it. In the paper's pixel units ``1/d`` is unbounded as d -> 0; measuring d in
    target radii and flooring it keeps the reward in ]0, 1]: it is 1 exactly when the target is
    reached and never 0 because the chamber is finite (d <= diagonal / unit).
    """
    return 1.0 / np.maximum(np.asarray(distance) / unit, 1.0)


def jaccard(plant: np.ndarray, target: np.ndarray) -> float:
    """Jaccard index |A ∩ G| / |A ∪ G| of two boolean pixel masks (0 when both are empty)."""
    union = np.count_nonzero(plant | target)
    return np.count_nonzero(plant & target) / union if union else 0.0
