"""What an oracle may know on a rig: the measured plant, the reached light, the task's target.

The simulator's oracles (``core/tasks/``) read a ``Chamber``: its plants, light and target,
and its photons (the simulator's light model: which points would attract growth). A photo
shows no photons, so ``oracle_chamber`` builds a chamber from a plant state (a camera's
measurement, or the simulator's own plants for comparison) whose photons are *candidates*: the
centres of the observation's pixels above the chamber's photon floor and farther than the
kill distance from every node (the simulator uses photons up there), with the plant's canopy
for shading (the light shines from above). The oracles' code then runs unchanged on
measured quantities only; with the simulator's plant in the same view the same policy gives
the reference return that the camera's return is compared with (scripts/bench_camera.py).
"""

from __future__ import annotations

import numpy as np

from growspace_sim.core import kernels
from growspace_sim.core.chamber import Chamber
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import Light
from growspace_sim.core.state import ChamberState


def candidate_points(cfg: SimConfig) -> np.ndarray:
    """The observation's pixel centres above the photon floor (complex x + iz, m), by x."""
    res = cfg.resolution
    x = (np.arange(res) + 0.5) * cfg.chamber_width / res
    z = cfg.chamber_height - (np.arange(res) + 0.5) * cfg.chamber_height / res
    points = (x[None, :] + 1j * z[:, None]).reshape(-1)
    points = points[points.imag >= cfg.photon_min_height * cfg.chamber_height]
    return np.sort(points)


def plant_view(state: ChamberState) -> ChamberState:
    """Only what a camera can measure of a state: plants, target, occupancy, light, steps."""
    n = state.n_nodes
    empty = np.zeros(0)
    return ChamberState(
        pos=state.pos[:n].copy(), parent=state.parent[:n].copy(),
        plant=state.plant[:n].copy(), has_child=state.has_child[:n].copy(),
        depth=state.depth[:n].copy(), ancestors=np.zeros((n, 1), np.int32),
        descendants=state.descendants[:n + 1].copy(), n_nodes=n,
        branch_counts=state.branch_counts.copy(), canopy=empty,
        photons=empty.astype(np.complex128), photon_x=empty,
        photon_column=empty.astype(np.intp), nearest_node=empty.astype(np.intp),
        nearest_distance=empty, available=empty.astype(bool), target=state.target,
        nearest=state.nearest.copy(), target_mask=state.target_mask,
        occupancy=state.occupancy.copy(), light=state.light.copy(), steps=state.steps,
        rng=np.random.default_rng(0))


def oracle_chamber(state: ChamberState, cfg: SimConfig, light: Light | None = None) -> Chamber:
    """A chamber an oracle can act on, built from a plant state and candidate photons.

    Args:
        state: The plants (a measured state, or ``plant_view`` of the simulator's).
        cfg: The chamber's configuration.
        light: The light as reached (default: the state's).

    Returns:
        A ``Chamber`` whose state holds those plants, the candidates not used up as photons
        and the canopy of the plants as they are now (shading).
    """
    chamber = Chamber(cfg)
    view = plant_view(state)
    if light is not None:
        view.light = light.copy()
    column_width = cfg.width_m(cfg.branch_thickness)
    columns = int(np.ceil(cfg.chamber_width / column_width))
    canopy = np.zeros(columns)
    half = 0.5 * column_width
    longest = max(cfg.branch_length_m, cfg.width_m(cfg.first_branch_height))
    pos, parent = view.pos, view.parent
    for i in np.flatnonzero(parent >= 0):
        a, b = complex(pos[parent[i]]), complex(pos[i])
        t = np.linspace(0.0, 1.0, int(max(longest, abs(b - a)) / column_width) + 2)
        kernels.shade(canopy, a, b, t, np.empty(t.size, np.complex128), half,
                      1.0 / column_width)
    photons = candidate_points(cfg)
    # The simulator uses up every photon a node comes within kill distance of: candidates
    # there would draw the shape oracle's spot to where nothing can grow any more.
    if view.n_nodes:
        gap = np.abs(photons[:, None] - pos[None, :view.n_nodes]).min(axis=1)
        photons = photons[gap >= cfg.width_m(cfg.kill_distance)]
    view.canopy = canopy
    view.photons, view.photon_x = photons, np.ascontiguousarray(photons.real)
    view.photon_column = np.minimum((view.photon_x / column_width).astype(np.intp),
                                    columns - 1)
    chamber.state = view
    return chamber
