"""Grow the plant to a goal (paper: 'control'): one plant, a target in the upper 25%, a beam
that starts above the stem. easy: the target is above the stem; hard: at the opposite side.

Reward: ``distance_reward`` of the plant's node nearest to the target (``common``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from growspace_sim.core.light import BEAM_ACTIONS
from growspace_sim.core.task import Layout, Task, register
from growspace_sim.core.tasks import common

if TYPE_CHECKING:
    from growspace_sim.core.chamber import Chamber
    from growspace_sim.core.config import SimConfig

CLOSE_IN = 3.0  # branch lengths: this close to the target, aim single photons at it


def layout(cfg: SimConfig, rng: np.random.Generator) -> Layout:
    """Target height, then stem and target x; the light starts above the stem."""
    target_z = common.target_height(cfg, rng)
    stem, target_x = common.one_stem(cfg, rng)
    return Layout((stem,), complex(target_x, target_z), light_x=stem)


class TargetOracle:
    """Steer one plant's lead node to the target (paper appendix).

    While the plant's node nearest to the target and the target share the beam, leave the light
    alone; otherwise steer the widest beam over that node, shifted towards the target so mostly
    photons on the target's side are lit; close to the target, light only the reachable photon
    nearest to it with the narrowest beam.
    """

    def act(self, chamber: Chamber) -> int:
        cfg, light, target = chamber.cfg, chamber.light, chamber.target
        widest = cfg.width_m(cfg.light_width_max)  # more lit photons, faster growth
        lead = common.leading_nodes(chamber)[0]
        near = abs(lead - target) < CLOSE_IN * cfg.branch_length_m
        photon = _photon_nearest_target(chamber) if near else None
        if photon is not None and abs(photon - target) < abs(lead - target):
            # Close in: light only the reachable photon that lies nearest to the target.
            return common.beam_action(chamber, photon.real, cfg.width_m(cfg.light_width_min))
        half = 0.5 * light.width
        if abs(target.real - light.x) <= half and abs(lead.real - light.x) <= half:
            # Lead and target share the beam: leave it. Moving or widening it would feed
            # side branches, which take growth slots (max_branching) from the lead.
            return BEAM_ACTIONS.index('stay')
        margin = common.LEAD * widest
        goal = lead.real + float(np.clip(target.real - lead.real, -margin, margin))
        return common.beam_action(chamber, goal, widest)


def _photon_nearest_target(chamber: Chamber) -> complex | None:
    photons = common.reachable_photons(chamber)
    if photons.size == 0:
        return None
    return complex(photons[np.argmin(np.abs(photons - chamber.target))])


TASK = register(Task(name='control', env_name='Control', layout=layout,
                     score=common.distance_score, oracle=TargetOracle))
