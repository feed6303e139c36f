"""Grow several plants fairly (paper: multi-objective): ``n_plants`` plants share one beam that
starts anywhere. easy: neighbours one light width apart, the target between them; hard: the
outer plants at opposite walls, the target in the middle.

Reward: the minimum over the plants of the control reward (``common.distance_score``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from growspace_sim.core.task import Layout, Task, register
from growspace_sim.core.tasks import common

if TYPE_CHECKING:
    from growspace_sim.core.chamber import Chamber
    from growspace_sim.core.config import SimConfig

ARRIVAL = 0.15  # of the chamber width: a plant this close to below the target has arrived


def layout(cfg: SimConfig, rng: np.random.Generator) -> Layout:
    """Target height, the stems and target x, then the light x."""
    target_z = common.target_height(cfg, rng)
    w, n = cfg.chamber_width, cfg.plant_count
    lo, hi = common.WALL_MARGIN * w, (1.0 - common.WALL_MARGIN) * w
    if cfg.setting == 'easy':  # neighbours one light width apart, target in their middle
        gap = cfg.width_m(cfg.light_width)
        span = gap * (n - 1)
        target_x = float(rng.uniform(lo + 0.5 * span, hi - 0.5 * span))
        stems = tuple(target_x + (i - 0.5 * (n - 1)) * gap for i in range(n))
    else:  # the outer plants at opposite walls, any others spread between, target mid-chamber
        anchors = np.linspace(0.2 * w, 0.8 * w, n)
        jitter = rng.uniform(-0.05 * w, 0.05 * w, n)
        stems = tuple(float(x) for x in np.clip(anchors + jitter, lo, hi))
        target_x = 0.5 * w + float(rng.uniform(-0.05, 0.05)) * w
    light_x = float(rng.uniform(0.0, w))
    return Layout(stems, complex(target_x, target_z), light_x=light_x)


class FairnessOracle:
    """One wide beam over all plants when it can reach them all; otherwise bring one plant at a
    time below the target, so the light alternates between the plants."""

    def __init__(self) -> None:
        self._focus = 0  # the plant the beam is working on

    def act(self, chamber: Chamber) -> int:
        cfg = chamber.cfg
        leads = common.leading_nodes(chamber)
        widest = cfg.width_m(cfg.light_width_max)
        margin = common.LEAD * widest
        span = leads.real.max() - leads.real.min() + 2.0 * margin
        if span <= widest:  # one beam can feed every plant
            return common.beam_action(chamber, 0.5 * (leads.real.max() + leads.real.min()),
                                      widest)
        lead = leads[self._next_focus(chamber, leads)]
        goal = lead.real + float(np.clip(chamber.target.real - lead.real, -margin, margin))
        return common.beam_action(chamber, goal, widest)

    def _next_focus(self, chamber: Chamber, leads: np.ndarray) -> int:
        """Bring one plant at a time below the target, then the next one.

        Moving the beam across the chamber costs many steps, so it stays with a plant until that
        plant has arrived instead of chasing the lowest reward at every step.
        """
        arrived = np.abs(leads.real - chamber.target.real) < ARRIVAL * chamber.cfg.chamber_width
        if chamber.steps == 0 or arrived[self._focus]:
            distance = np.abs(leads.real - chamber.light.x)
            self._focus = int(np.argmin(np.where(arrived, np.inf, distance)))
        return self._focus


TASK = register(Task(name='fairness', env_name='Fairness', layout=layout,
                     score=common.distance_score, multi_plant=True, oracle=FairnessOracle))
