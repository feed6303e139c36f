"""Where a resumed chamber starts: a recording re-simulated to its last step.

``replay.resume_point`` computes it; ``ChamberNode(..., resume=...)`` starts from it.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from growspace_sim.simulation import Simulation


@dataclasses.dataclass
class ResumePoint:
    """A chamber re-simulated to the last recorded step of a recording, ready to go on.

    Attributes:
        sim: The simulation, in the state the recorded chamber had after its last step.
        outcome: The last step's (or the reset's) outcome.
        seed: The seed of the last episode; None where it continued the random stream.
        reset_id: The last episode's reset_id.
        last_step_id: The highest step_id the chamber answered in it (lockstep).
        sim_time_ns: The sim time of the last step [ns] (its StepResult's stamp).
        episode_over: The last episode ended (truncated or terminated).
    """

    sim: Simulation
    outcome: Any
    seed: int | None
    reset_id: int
    last_step_id: int
    sim_time_ns: int
    episode_over: bool
    report: Any  # replay.ResimReport: the check of every recorded step

    @property
    def steps(self) -> int:
        """Steps of the last episode done."""
        return self.sim.chamber.steps
