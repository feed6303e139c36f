"""What the built-in challenges share: layout draws, the two rewards, oracle steering.

Layouts follow the paper (section 'Tasks') and the README's challenge table. Every random draw
goes through the episode's ``np.random.Generator``, in a fixed order, so an episode is a
function of its seed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from growspace_sim.core.light import BEAM_ACTIONS
from growspace_sim.core.task import Score

if TYPE_CHECKING:
    from growspace_sim.core.chamber import Chamber
    from growspace_sim.core.config import SimConfig
    from growspace_sim.core.state import ChamberState

WALL_MARGIN = 0.05  # fraction of the width kept free between a stem and a wall
LEAD = 0.4  # of the beam width: how far ahead of the plant, towards the target, oracles aim


def target_height(cfg: SimConfig, rng: np.random.Generator) -> float:
    """The target's height (m), 'in the upper 25%' of the chamber: every layout's first draw."""
    h = cfg.chamber_height
    return float(rng.uniform(0.75 * h, h))


def one_stem(cfg: SimConfig, rng: np.random.Generator) -> tuple[float, float]:
    """(stem x, target x) in m. easy: the target above the stem; hard: at opposite sides."""
    w = cfg.chamber_width
    if cfg.setting == 'easy':
        stem = float(rng.uniform(0.1 * w, 0.9 * w))
        return stem, stem + float(rng.uniform(-0.05, 0.05)) * w
    near = float(rng.uniform(WALL_MARGIN * w, 0.2 * w))
    far = float(rng.uniform(0.8 * w, (1.0 - WALL_MARGIN) * w))
    if rng.integers(2):
        near, far = w - near, w - far
    return near, far


def distance_reward(distance: np.ndarray | float, unit: float) -> np.ndarray | float:
    """The paper's eq. 4 term ``1/d`` for one plant, with d measured in target radii.

    ``d`` is the Euclidean distance (m) from the plant's nearest node to the target centre,
    divided by the target radius ``unit`` (m) and floored at 1: a node inside the target disc
    has reached it. In the paper's pixel units ``1/d`` is unbounded as d -> 0; measuring d in
    target radii and flooring it keeps the reward in ]0, 1]: it is 1 exactly when the target is
    reached and never 0 because the chamber is finite (d <= diagonal / unit).
    """
    return 1.0 / np.maximum(np.asarray(distance) / unit, 1.0)


def distance_score(state: ChamberState, cfg: SimConfig) -> Score:
    """Reward of the point-target challenges: the worst plant's ``distance_reward`` (with one
    plant, its own); success when every plant reached the target disc."""
    plant_rewards = distance_reward(state.nearest, cfg.width_m(cfg.target_radius))
    reward = float(plant_rewards.min())
    return reward, plant_rewards, reward >= 1.0


def jaccard(plant: np.ndarray, target: np.ndarray) -> float:
    """Jaccard index |A ∩ G| / |A ∪ G| of two boolean pixel masks (0 when both are empty)."""
    union = np.count_nonzero(plant | target)
    return np.count_nonzero(plant & target) / union if union else 0.0


def reachable_photons(chamber: Chamber) -> np.ndarray:
    """Unshaded photons within the radius of influence of some node (complex, m)."""
    photons = chamber.photons[~chamber.shaded]
    nodes = chamber.pos[:chamber.n_nodes]
    if photons.size == 0:
        return photons
    gap = np.abs(photons[:, None] - nodes).min(axis=1)
    return photons[gap < chamber.cfg.width_m(chamber.cfg.radius_of_influence)]


def leading_nodes(chamber: Chamber) -> np.ndarray:
    """Per plant, its node nearest to the target (complex, m)."""
    nodes = chamber.pos[:chamber.n_nodes]
    owner = chamber.plant[:chamber.n_nodes]
    distance = np.abs(nodes - chamber.target)
    return np.array([nodes[owner == p][np.argmin(distance[owner == p])]
                     for p in range(chamber.cfg.plant_count)])


def beam_action(chamber: Chamber, centre: float, width: float) -> int:
    """The discrete action that brings the beam closest to (centre, width): move, then resize."""
    step, light = chamber.cfg.light_step_m, chamber.light
    move = towards(centre - light.x, step, 'left', 'right')
    if move == 'stay':
        move = towards(width - light.width, step, 'narrower', 'wider')
    return BEAM_ACTIONS.index(move)


def towards(error: float, step: float, negative: str, positive: str) -> str:
    """The action name that reduces ``error`` by one ``step``, or 'stay' within half a step."""
    if error > 0.5 * step:
        return positive
    if error < -0.5 * step:
        return negative
    return 'stay'
