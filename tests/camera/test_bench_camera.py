"""scripts/bench_camera.py's own judgement: which simulator tips a side photo cannot show."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from growspace_sim.core.config import SimConfig
from growspace_sim.simulation import Simulation

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location('bench_camera', ROOT / 'scripts' / 'bench_camera.py')
bench = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bench)


def fake_chamber(pos: list[complex], parent: list[int], plant: list[int],
                 thickness_m: float = 0.01) -> SimpleNamespace:
    """The parts of a ``Chamber`` that ``hidden_tips`` reads."""
    parent_a = np.array(parent)
    has_child = np.isin(np.arange(len(pos)), parent_a)
    return SimpleNamespace(
        n_nodes=len(pos), pos=np.array(pos), parent=parent_a,
        state=SimpleNamespace(plant=np.array(plant)),
        cfg=SimpleNamespace(plant_count=max(plant) + 1),
        tips=lambda: np.flatnonzero(~has_child),
        thickness=lambda: np.full(len(pos), thickness_m))


def test_a_tip_inside_another_stem_is_hidden_and_tips_come_plant_by_plant():
    # Two stems (1 cm thick); plant 1's tip is node 4, plant 0's are 5 (a shoot turned back
    # down its own stem, ending 1 mm off its axis) and 6 (clear of everything).
    chamber = fake_chamber(
        pos=[0.3, 0.6, 0.3 + 0.3j, 0.6 + 0.3j, 0.7 + 0.4j, 0.301 + 0.1j, 0.35 + 0.4j],
        parent=[-1, -1, 0, 1, 3, 2, 2],
        plant=[0, 1, 0, 1, 1, 0, 0])
    # tip_positions' order: plant 0's tips (5, 6), then plant 1's (4)
    assert bench.hidden_tips(chamber).tolist() == [True, False, False]


def test_a_bud_on_its_stem_is_hidden_but_not_one_a_stem_width_away():
    chamber = fake_chamber(pos=[0.4, 0.4 + 0.3j, 0.4 + 0.304j, 0.406 + 0.15j],
                           parent=[-1, 0, 1, 1], plant=[0, 0, 0, 0])
    # node 2: 4 mm above the stem's top, inside its 5 mm half width around the end point;
    # node 3: 6 mm beside the stem's axis, outside it (its own segment does not count)
    assert bench.hidden_tips(chamber).tolist() == [True, False]


def test_one_flag_per_simulator_tip_on_a_grown_chamber():
    sim = Simulation(SimConfig(challenge='fairness'))
    sim.reset(seed=3)
    for _ in range(30):
        sim.step()
    hidden = bench.hidden_tips(sim.chamber)
    assert hidden.shape == (len(np.concatenate(sim.chamber.tip_positions())),)
    assert hidden.dtype == bool
