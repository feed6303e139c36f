"""The measured plants in the simulator's own terms: a ``ChamberState``, its reward, its image.

The reward is the challenge's own ``Task.score`` called on a ``ChamberState`` built from the
measurement, and the observation is the simulator's own ``Renderer`` drawing that state, so
neither rule is written twice. What a photo cannot show is left empty, never copied from a
simulator: the photons (the simulator's light model, not a thing in the chamber), the canopy
used for shading, and the node ancestry beyond parents. The fields a task's score reads for the
built-in challenges (``nearest`` for the distance rewards, ``occupancy`` against
``target_mask`` for shape) are measured; see docs/hardware.md for the list.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from growspace_camera.errors import BAD_INPUT, CameraError, NO_PLANT, PLANTS
from growspace_camera.nodes import PlantTree
from growspace_sim.core import kernels
from growspace_sim.core.chamber import Chamber
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import Light
from growspace_sim.core.state import ChamberState
from growspace_sim.core.task import Score
from growspace_sim.render import Renderer

NOT_MEASURED = ('photons (the simulator light model), canopy (its shading columns), '
                'ancestors beyond the parent, and which of two overlapping branches is which')


@dataclass(frozen=True)
class Target:
    """The challenge's goal for this episode (from the task, never from the photo).

    Attributes:
        point: The point target (x + iz) [m]; None for a shape target.
        mask: (res, res) bool digit pixels of a shape target; None for a point target.
    """

    point: complex | None = None
    mask: np.ndarray | None = None

    def check(self, cfg: SimConfig) -> None:
        """Raises CameraError ``BAD_INPUT`` if this target does not fit the challenge."""
        if cfg.task.digits is None:
            if self.point is None or not (math.isfinite(self.point.real)
                                          and math.isfinite(self.point.imag)):
                raise CameraError(BAD_INPUT, f'the {cfg.challenge} challenge needs a finite '
                                  f'point target, got {self.point!r}')
        elif self.mask is None or self.mask.shape != (cfg.resolution, cfg.resolution):
            got = None if self.mask is None else self.mask.shape
            raise CameraError(BAD_INPUT, f'the {cfg.challenge} challenge needs a '
                              f'{cfg.resolution} x {cfg.resolution} target mask, got {got}')


def measured_state(tree: PlantTree, cfg: SimConfig, light: Light, target: Target,
                   steps: int) -> ChamberState:
    """A ``ChamberState`` holding the measured plants (see the module docstring).

    Raises:
        CameraError: ``PLANTS`` when the photo has another number of stem bases than the
            challenge has plants; ``BAD_INPUT`` for a target or light that does not fit it.
    """
    if tree.plants != cfg.plant_count:
        raise CameraError(PLANTS, f'{tree.plants} stem base(s) in the photo, the {cfg.challenge} '
                          f'challenge has {cfg.plant_count} plant(s)')
    # A plant is at least its first stem: one measured as a base alone would score as no plant
    # (a reward of 0), a number the photo did not give.
    bare = sorted(set(range(tree.plants)) - set(tree.plant[tree.plants:].tolist()))
    if bare:
        raise CameraError(NO_PLANT, f'plant(s) {bare}: a stem base with nothing measured '
                          f'above it')
    target.check(cfg)
    if light.spot != cfg.uses_spotlight:
        raise CameraError(BAD_INPUT, f'the {cfg.challenge} challenge has a '
                          f'{"spotlight" if cfg.uses_spotlight else "beam"}, the light given '
                          f'is a {"spotlight" if light.spot else "beam"}')
    n = len(tree.nodes)
    pos = tree.nodes[:, 0] + 1j * tree.nodes[:, 1]
    parent = tree.parent.astype(np.int32)
    has_child = np.zeros(n, bool)
    has_child[parent[parent >= 0]] = True
    depth = np.zeros(n, np.int32)
    descendants = np.zeros(n + 1, np.int32)  # [i + 1]: nodes above node i, as in the core
    for i in range(n):  # parents come first
        if parent[i] >= 0:
            depth[i] = depth[parent[i]] + 1
    for i in range(n - 1, -1, -1):
        if parent[i] >= 0:
            descendants[parent[i] + 1] += descendants[i + 1] + 1
    plants = cfg.plant_count
    grown = np.arange(n) >= plants  # the roots are not nodes the reward reads
    nearest = np.full(plants, np.inf)
    if target.point is not None:
        distance = np.abs(pos - target.point)
        for p in range(plants):
            mine = grown & (tree.plant == p)
            if mine.any():
                nearest[p] = distance[mine].min()
    res = cfg.resolution
    occupancy = np.zeros((res, res), bool)
    if target.mask is not None:
        rasterise(occupancy, pos, parent, cfg)
    empty = np.zeros(0)
    return ChamberState(
        pos=pos, parent=parent, plant=tree.plant.astype(np.int16), has_child=has_child,
        depth=depth, ancestors=np.zeros((n, 1), np.int32), descendants=descendants, n_nodes=n,
        branch_counts=np.bincount(tree.plant[grown], minlength=plants).astype(np.int64),
        canopy=empty, photons=empty.astype(np.complex128), photon_x=empty,
        photon_column=empty.astype(np.intp), nearest_node=empty.astype(np.intp),
        nearest_distance=empty, available=empty.astype(bool),
        target=target.point if cfg.task.digits is None else None, nearest=nearest,
        target_mask=target.mask, occupancy=occupancy, light=light, steps=steps,
        rng=np.random.default_rng(0))  # the core's field; nothing here draws from it


def score(state: ChamberState, cfg: SimConfig) -> Score:
    """The challenge's reward of a measured state: ``cfg.task.score``, the simulator's code."""
    return cfg.task.score(state, cfg)


class Observer:
    """Draws measured states with the simulator's ``Renderer`` (one per configuration)."""

    def __init__(self) -> None:
        self._cfg: SimConfig | None = None
        self._chamber: Chamber | None = None
        self._renderer: Renderer | None = None

    def image(self, state: ChamberState, cfg: SimConfig) -> np.ndarray:
        """The (res, res, 3) uint8 RGB observation: target red, plant green, light blue."""
        if cfg != self._cfg:
            self._cfg, self._chamber, self._renderer = cfg, Chamber(cfg), Renderer(cfg)
        chamber, renderer = self._chamber, self._renderer
        chamber.state = state  # a chamber is its state: the renderer reads it through views
        renderer.reset(chamber)  # every photo is a new plant: draw all of it
        return renderer.render(chamber)


def rasterise(occupancy: np.ndarray, pos: np.ndarray, parent: np.ndarray,
              cfg: SimConfig) -> None:
    """Mark the pixels each segment passes (its centre line, as the shape reward counts them),
    with the simulator's own rasteriser, on a square grid over the chamber of any size."""
    res = occupancy.shape[0]
    pixel = cfg.chamber_width / res
    longest = max(cfg.branch_length_m, cfg.width_m(cfg.first_branch_height))
    for i in np.flatnonzero(parent >= 0):
        a, b = complex(pos[parent[i]]), complex(pos[i])
        steps = np.linspace(0.0, 1.0, int(max(longest, abs(b - a)) / (0.5 * pixel)) + 2)
        points = np.empty(steps.size, np.complex128)
        kernels.rasterise(occupancy, a, b, steps, points, res / cfg.chamber_width,
                          res / cfg.chamber_height, cfg.chamber_height)
