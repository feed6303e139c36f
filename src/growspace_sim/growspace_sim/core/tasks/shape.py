"""Grow the plant into a shape (paper: multi-objective): a 28 x 28 chamber image, a spotlight
that starts above the stem and an MNIST digit as the target (easy: 3, hard: 0; the config's
``digits`` overrides). The adapter draws the digit image (``growspace_sim.digits``).

Reward: the Jaccard index of the plant's pixels and the digit's pixels (the light is neither).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from growspace_sim.core.light import SPOT_ACTIONS
from growspace_sim.core.task import Layout, Score, Task, register
from growspace_sim.core.tasks import common

if TYPE_CHECKING:
    from growspace_sim.core.chamber import Chamber
    from growspace_sim.core.config import SimConfig
    from growspace_sim.core.state import ChamberState


def layout(cfg: SimConfig, rng: np.random.Generator) -> Layout:
    """The stem in the middle (MNIST digits are centred in their frame), the spotlight on its
    tip."""
    common.target_height(cfg, rng)  # unused, drawn so that seeds keep giving the same episodes
    stem = 0.5 * cfg.chamber_width
    tip_z = cfg.width_m(cfg.first_branch_height)
    return Layout((stem,), None, stem, tip_z + cfg.width_m(cfg.spot_radius))


def score(state: ChamberState, cfg: SimConfig) -> Score:
    """Jaccard index of plant and digit pixels; success from ``shape_success`` on."""
    reward = common.jaccard(state.occupancy, state.target_mask)
    return reward, np.array([reward]), reward >= cfg.shape_success


class ShapeOracle:
    """Fill the digit bottom-up: spot the lowest reachable photon in an uncovered digit pixel;
    without one, the reachable photon nearest to an uncovered digit pixel."""

    def act(self, chamber: Chamber) -> int:
        cfg, light = chamber.cfg, chamber.light
        photons = common.reachable_photons(chamber)
        rows, cols = np.nonzero(chamber.target_mask & ~chamber.occupancy)
        if photons.size == 0 or rows.size == 0:
            return SPOT_ACTIONS.index('stay')
        pixel = cfg.chamber_width / cfg.resolution
        wanted = (cols + 0.5) * pixel + 1j * (cfg.chamber_height - (rows + 0.5) * pixel)
        gap = np.abs(photons[:, None] - wanted).min(axis=1)
        inside = gap < 0.75 * pixel
        if inside.any():
            goal = photons[inside][np.argmin(photons[inside].imag)]
        else:
            goal = photons[np.argmin(gap)]
        step = cfg.light_step_m
        dx, dz = goal.real - light.x, goal.imag - light.z
        if abs(dx) >= abs(dz):
            return SPOT_ACTIONS.index(common.towards(dx, step, 'left', 'right'))
        return SPOT_ACTIONS.index(common.towards(dz, step, 'down', 'up'))


TASK = register(Task(
    name='shape', env_name='Shape', layout=layout, score=score, spotlight=True, resolution=28,
    digits={'easy': (3,), 'hard': (0,)}, oracle=ShapeOracle,
    extra_envs={
        'GrowSpace/Shape-AllDigits-v0': ('growspace_sim.envs.env:GrowSpaceEnv',
                                         {'challenge': 'shape', 'digits': tuple(range(10))}),
        'GrowSpace/Shape-Curriculum-v0': ('growspace_sim.envs.env:make_curriculum',
                                          {'challenge': 'shape'}),
    }))
