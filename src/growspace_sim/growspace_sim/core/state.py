"""The state of one chamber episode: every array the growth reads and writes, in one object.

``Chamber.reset`` creates it (the one place) and ``Chamber.step`` grows it in place: the node
arrays are preallocated for the whole episode (``capacity`` slots, the first ``n_nodes`` used)
so a step only appends. Positions are complex numbers ``x + 1j * z`` in metres, chamber frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from growspace_sim.core.light import Light


@dataclass(eq=False)
class ChamberState:
    """One episode of a chamber (a plain container: ``Chamber`` keeps it consistent)."""

    # plants: node i for i < n_nodes; the first plant_count nodes are the roots
    pos: np.ndarray  # (capacity,) complex128, m, node position
    parent: np.ndarray  # (capacity,) int32, parent node, -1 for a root
    plant: np.ndarray  # (capacity,) int16, the plant a node belongs to
    has_child: np.ndarray  # (capacity,) bool, False for a branch tip
    depth: np.ndarray  # (capacity,) int32, segments between the node and its root
    ancestors: np.ndarray  # (capacity, window) int32, 1 + ancestor at column depth % window
    descendants: np.ndarray  # (capacity + 1,) int32, [i + 1]: nodes above node i; [0] unused
    n_nodes: int  # nodes in use
    branch_counts: np.ndarray  # (plant_count,) int64, segments per plant
    canopy: np.ndarray  # (columns,) float64, m, top of the plants per column (shading)
    # photons, sorted by x so that the photons of an x range are one slice
    photons: np.ndarray  # (M,) complex128, m
    photon_x: np.ndarray  # (M,) float64, m, photons.real contiguous
    photon_column: np.ndarray  # (M,) intp, canopy column above each photon
    nearest_node: np.ndarray  # (M,) intp, the node nearest to each photon
    nearest_distance: np.ndarray  # (M,) float64, m, distance to that node
    available: np.ndarray  # (M,) bool, would attract if lit: a node in reach, nothing above
    # the goal and the reward's incremental inputs
    target: complex | None  # m, the point target; None for a shape target
    nearest: np.ndarray  # (plant_count,) float64, m, each plant's closest node to the target
    target_mask: np.ndarray | None  # (res, res) bool, shape target pixels; None for a point
    occupancy: np.ndarray  # (res, res) bool, pixels the plants cover (with a shape target)
    light: Light  # the light as it is now (actions change it in place)
    steps: int  # steps taken in the episode
    rng: np.random.Generator  # the episode's random stream (bud choice when too many attract)
