"""Find the plant (paper: multi-stage): as ``control``, but the light starts anywhere, so an
agent must first find the plant, then grow it to the target. Same reward and oracle."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from growspace_sim.core.task import Layout, Task, register
from growspace_sim.core.tasks import common, control

if TYPE_CHECKING:
    from growspace_sim.core.config import SimConfig


def layout(cfg: SimConfig, rng: np.random.Generator) -> Layout:
    """Target height, stem and target x as in control, then the light x."""
    target_z = common.target_height(cfg, rng)
    stem, target_x = common.one_stem(cfg, rng)
    light_x = float(rng.uniform(0.0, cfg.chamber_width))
    return Layout((stem,), complex(target_x, target_z), light_x=light_x)


TASK = register(Task(name='find_plant', env_name='FindPlant', layout=layout,
                     score=common.distance_score, oracle=control.TargetOracle))
