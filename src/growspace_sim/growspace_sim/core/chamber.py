"""The growth chamber: photons, plants and light, advanced by the Space Colonization Algorithm.

SCA (Runions et al. 2007) as GrowSpace uses it: every node of a plant is a bud. Each lit photon
attracts only the node nearest to it, if that node lies within the radius of influence. A bud
attracted by photons grows one new segment of fixed length along the normalised sum of the unit
vectors towards its photons. Photons closer than the kill distance to a new node are used up.
At most ``max_branching`` buds grow per step; when more are attracted, a seeded draw picks them.

Light decides which photons take part: those inside the beam or spotlight and, with shading,
not under any part of a plant (the light shines from above). The chamber keeps the height of the
plant's top over columns one branch thickness wide; a photon below it is in the shade.

Positions are complex numbers ``x + 1j * z`` in metres: one array holds a 2-D point set, ``abs``
is the Euclidean distance, and vector sums stay one operation. Arrays are preallocated for the
whole episode so a step only appends. Photons never move and nodes are only added, so each
photon keeps its nearest node and that distance, updated against the new nodes only: a step
costs (photons x new nodes) instead of (lit photons x all nodes).

The episode's arrays live in one ``ChamberState`` (``core.state``), created by ``reset``; the
challenge's ``Task`` (``cfg.task``) decides the layout and the reward. A step's work on them is
done by the compiled kernels of ``core.kernels``; this class draws from the episode's random
stream, keeps the state consistent and offers the views adapters read. When photons are used
up, the survivors move to the front of their arrays and the state's photon arrays become
shorter views of them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from growspace_sim.core import kernels
from growspace_sim.core import light as lights
from growspace_sim.core.config import SimConfig
from growspace_sim.core.state import ChamberState

ANCESTOR_WINDOW = 64  # ancestors listed per node: deeper ones cost one more gather per 64 levels


class StepOutcome(NamedTuple):
    """What one step produced (a named tuple: built on every step, it must be cheap)."""

    reward: float  # the challenge's reward for this step
    plant_rewards: np.ndarray  # (n_plants,) float64; per-plant reward (target challenges)
    success: bool  # target reached by every plant / shape matched well enough
    truncated: bool  # the episode reached its length
    new_segments: int  # segments grown this step


class Chamber:
    """One chamber: call ``reset`` to begin an episode, then ``step`` once per action.

    The chamber holds what the configuration fixes; the episode is ``state``. Its read-only
    views (``pos``, ``light``, ``tips()``, ...) are what adapters, oracles and tests read.

    Args:
        cfg: the validated configuration.
    """

    def __init__(self, cfg: SimConfig) -> None:
        self.cfg = cfg
        self.task = cfg.task
        w = cfg.chamber_width
        self._res = cfg.resolution
        self._half_thickness = 0.5 * cfg.width_m(cfg.branch_thickness)
        self._influence = cfg.width_m(cfg.radius_of_influence)
        self._kill = cfg.width_m(cfg.kill_distance)
        self._branch_length = cfg.branch_length_m
        self._pixel = w / self._res  # m
        self._column_width = cfg.width_m(cfg.branch_thickness)  # m, shading resolution
        self._columns = int(math.ceil(w / self._column_width))
        self._longest = max(cfg.branch_length_m, cfg.width_m(cfg.first_branch_height))
        self._capacity = 2 * cfg.plant_count + cfg.max_branching * cfg.episode_length
        self._column_steps = self._steps(self._column_width)  # canopy samples per segment
        self._pixel_steps = self._steps(0.5 * self._pixel)  # occupancy samples per segment
        # the kernels' work arrays (np.zeros: pages are mapped only as nodes grow)
        self._pull = np.zeros(self._capacity, np.complex128)  # per node: sum of unit vectors
        self._strength = np.zeros(self._capacity)  # its length
        self._buds = np.zeros(self._capacity, np.intp)
        self._new = np.zeros(cfg.max_branching, np.complex128)
        self._window = min(cfg.episode_length + 2, ANCESTOR_WINDOW)
        self._deep = cfg.episode_length + 2 > ANCESTOR_WINDOW  # a node can outgrow its row
        self.state: ChamberState | None = None
        self._outcome_cache: tuple[float, np.ndarray, bool] | None = None
        self._tips_cache: tuple[np.ndarray, ...] | None = None

    # ------------------------------------------------------------------ episode start
    def reset(self, rng: np.random.Generator,
              target_image: np.ndarray | None = None) -> ChamberState:
        """Begin an episode drawn from ``rng``: the task's layout, then the photons.

        Args:
            rng: the episode's generator; layout and photons are drawn from it in a fixed order,
                and it stays the episode's stream (``state.rng``).
            target_image: the 28 x 28 digit of a task with shape targets (uint8, ink > 127).

        Returns:
            The new episode's state (also ``self.state``).

        Raises:
            ValueError: if a shape task gets no target image or one of the wrong shape.
        """
        cfg = self.cfg
        layout = self.task.layout(cfg, rng)
        n, cap = cfg.plant_count, self._capacity
        target_mask = None if self.task.digits is None else self._target_mask(target_image)
        pos = np.zeros(cap, np.complex128)
        roots = np.asarray(layout.stem_x, np.complex128)
        pos[:n] = roots  # roots have no parent and no segment
        plant = np.zeros(cap, np.int16)
        plant[:n] = np.arange(n)
        canopy = np.zeros(self._columns)
        photons, photon_x, column, nearest_node, nearest_distance = self._index_photons(
            self._scatter_photons(rng), roots)
        self.state = state = ChamberState(
            pos=pos, parent=np.full(cap, -1, np.int32), plant=plant,
            has_child=np.zeros(cap, bool), depth=np.zeros(cap, np.int32),
            # np.zeros leaves untouched rows unmapped: memory grows with the nodes grown
            ancestors=np.zeros((cap, self._window), np.int32),
            descendants=np.zeros(cap + 1, np.int32), n_nodes=n,
            branch_counts=np.zeros(n, np.int64), canopy=canopy,
            photons=photons, photon_x=photon_x, photon_column=column,
            nearest_node=nearest_node, nearest_distance=nearest_distance,
            available=self._available(nearest_distance, canopy, column, photons),
            target=layout.target, nearest=np.full(n, np.inf), target_mask=target_mask,
            occupancy=np.zeros((self._res, self._res), bool),
            light=lights.initial_light(cfg, layout.light_x, layout.light_z), steps=0, rng=rng)
        self._bind(state)
        self._append(state, roots + 1j * cfg.width_m(cfg.first_branch_height), np.arange(n))
        return state

    def set_photons(self, photons: np.ndarray) -> None:
        """Replace the photons (complex x + iz, m) of the current episode: crafted scenarios.

        Raises:
            ValueError: if a photon is not finite or lies outside the chamber.
        """
        photons = np.asarray(photons, np.complex128).reshape(-1)
        cfg, s = self.cfg, self.state
        bad = ~np.isfinite(photons) | (photons.real < 0) | (photons.real > cfg.chamber_width) \
            | (photons.imag < 0) | (photons.imag > cfg.chamber_height)
        if bad.any():
            raise ValueError(f'photon {photons[bad][0]!r} is not inside the chamber '
                             f'[0, {cfg.chamber_width}] x [0, {cfg.chamber_height}] m.')
        s.photons, s.photon_x, s.photon_column, s.nearest_node, s.nearest_distance = \
            self._index_photons(photons, s.pos[:s.n_nodes])
        s.available = self._available(s.nearest_distance, s.canopy, s.photon_column, s.photons)

    def _index_photons(self, photons: np.ndarray, nodes: np.ndarray) -> tuple[np.ndarray, ...]:
        """Photons sorted by x, their x, canopy column, nearest node and its distance (which
        then only change when a node grows closer)."""
        photons = np.sort(photons)  # complex numbers sort by real part first
        photon_x = np.ascontiguousarray(photons.real)
        distances = np.abs(photons[:, None] - nodes)
        nearest_node = distances.argmin(axis=1)  # ties go to the older node
        nearest_distance = distances[np.arange(photons.size), nearest_node]
        return photons, photon_x, self._column_of(photon_x), nearest_node, nearest_distance

    def _available(self, distance: np.ndarray, canopy: np.ndarray, column: np.ndarray,
                   photons: np.ndarray) -> np.ndarray:
        """Flag the photons that would attract if lit: a node within reach, nothing above.

        Both only change when the plant grows, so a step without growth reads this as it is.
        """
        available = np.empty(photons.size, bool)
        kernels.mark_available(available, photons, column, distance, canopy, self._influence,
                               self.cfg.shading)
        return available

    def _scatter_photons(self, rng: np.random.Generator) -> np.ndarray:
        cfg = self.cfg
        count = cfg.light_density
        x = rng.uniform(0.0, cfg.chamber_width, count)
        z = rng.uniform(cfg.photon_min_height * cfg.chamber_height, cfg.chamber_height, count)
        return x + 1j * z

    def _target_mask(self, image: np.ndarray | None) -> np.ndarray:
        if image is None:
            raise ValueError(f'the {self.task.name} challenge needs a target_image '
                             f'(a 28 x 28 digit).')
        image = np.asarray(image)
        if image.shape != (28, 28):
            raise ValueError(f'target_image must be 28 x 28, got shape {image.shape}.')
        index = np.arange(self._res) * 28 // self._res  # nearest-neighbour resize
        return image[np.ix_(index, index)] > 127

    # ------------------------------------------------------------------ one step
    def step(self) -> StepOutcome:
        """Grow one step under the current light (set it first: actions act at once).

        Raises:
            RuntimeError: if the episode has ended or ``reset`` was never called.
        """
        state = self.state
        if state is None or state.steps >= self.cfg.episode_length:
            raise RuntimeError('the episode is over; call reset() first.')
        grown = self._grow(state)
        state.steps += 1
        return self._outcome(grown)

    def _grow(self, s: ChamberState) -> int:
        light = s.light
        half_span = light.radius if light.spot else 0.5 * light.width
        count, grown = kernels.grow(
            s.photons, s.photon_x, s.nearest_node, s.nearest_distance, s.available, s.n_nodes,
            light.x - half_span, light.x + half_span, light.spot, complex(light.x, light.z),
            light.radius, *self._grow_args)
        if grown < 0:  # more buds than may grow: a seeded draw picks them
            buds = np.sort(s.rng.choice(self._buds[:count], self.cfg.max_branching,
                                        replace=False))
            grown = kernels.sprout(buds, *self._sprout_args)
        else:
            buds = self._buds
        if grown:
            self._append(s, self._new[:grown], buds[:grown])
        return grown

    def _append(self, s: ChamberState, new: np.ndarray, parents: np.ndarray) -> None:
        """Add nodes with segments to their parents and update what depends on them."""
        start = s.n_nodes
        s.n_nodes = start + new.size
        left = kernels.append(new, parents, start, s.photons, s.photon_x, s.photon_column,
                              s.nearest_node, s.nearest_distance, s.available,
                              *self._append_args)
        if left < s.photons.size:  # the survivors are the first ones: keep those
            s.photons, s.photon_x, s.photon_column = \
                s.photons[:left], s.photon_x[:left], s.photon_column[:left]
            s.nearest_node, s.nearest_distance, s.available = \
                s.nearest_node[:left], s.nearest_distance[:left], s.available[:left]
        self._outcome_cache = self._tips_cache = None

    def _bind(self, s: ChamberState) -> None:
        """Gather the kernels' arguments that stay the same for the whole episode."""
        cfg, target = self.cfg, s.target is not None
        self._sprout_args = (self._pull, self._strength, s.pos, self._branch_length,
                             cfg.chamber_width, cfg.chamber_height, self._new)
        self._grow_args = (cfg.max_branching, self._buds) + self._sprout_args
        self._append_args = (
            s.pos, s.parent, s.plant, s.has_child, s.depth, s.ancestors, s.descendants,
            self._deep, s.branch_counts, target, s.target if target else 0j, s.nearest,
            s.target_mask is not None, s.occupancy, self._pixel_steps,
            self._res / cfg.chamber_width, self._res / cfg.chamber_height, cfg.chamber_height,
            s.canopy, self._column_steps, self._half_thickness, 1.0 / self._column_width,
            self._kill, self._influence, cfg.shading)

    def _column_of(self, x: np.ndarray) -> np.ndarray:
        column = (x * (1.0 / self._column_width)).astype(np.intp)
        return np.minimum(np.maximum(column, 0), self._columns - 1)

    def _steps(self, spacing: float) -> np.ndarray:
        """Where to sample a segment (of at most one branch length), at most ``spacing`` apart:
        fractions of its length from 0 to 1."""
        return np.linspace(0.0, 1.0, int(self._longest / spacing) + 2)

    def _outcome(self, grown: int) -> StepOutcome:
        if self._outcome_cache is None:  # the reward changes only when the plant grows
            self._outcome_cache = self.task.score(self.state, self.cfg)
        reward, plant_rewards, success = self._outcome_cache
        return StepOutcome(reward, plant_rewards.copy(), success,
                           self.state.steps >= self.cfg.episode_length, grown)

    # ------------------------------------------------------------------ views
    def current_reward(self) -> StepOutcome:
        """The reward of the current state, as a step would report it (used after reset)."""
        return self._outcome(0)

    # State fields that adapters, oracles and tests read (the arrays are the state's own).
    @property
    def pos(self) -> np.ndarray:
        """(capacity,) complex128 node positions (m); the first ``n_nodes`` are in use."""
        return self.state.pos

    @property
    def parent(self) -> np.ndarray:
        """(capacity,) int32 parent of each node, -1 for a root."""
        return self.state.parent

    @property
    def plant(self) -> np.ndarray:
        """(capacity,) int16 plant of each node."""
        return self.state.plant

    @property
    def n_nodes(self) -> int:
        return self.state.n_nodes

    @property
    def photons(self) -> np.ndarray:
        """(M,) complex128 remaining photons (m), sorted by x; later steps overwrite it in place
        (copy it to keep it)."""
        return self.state.photons

    @property
    def light(self) -> lights.Light | None:
        """The light (actions change it in place); None before the first reset."""
        return None if self.state is None else self.state.light

    @property
    def target(self) -> complex | None:
        """The point target (m), None for a shape target."""
        return self.state.target

    @property
    def target_mask(self) -> np.ndarray | None:
        """(res, res) bool shape target pixels, None for a point target."""
        return self.state.target_mask

    @property
    def occupancy(self) -> np.ndarray:
        """(res, res) bool pixels the plants cover (kept with a shape target only)."""
        return self.state.occupancy

    @property
    def steps(self) -> int:
        return 0 if self.state is None else self.state.steps

    @property
    def nodes(self) -> np.ndarray:
        """(N, 2) float64 node positions (x, z) in metres; a copy."""
        pos = self.state.pos[:self.state.n_nodes]
        return np.column_stack((pos.real, pos.imag))

    @property
    def shaded(self) -> np.ndarray:
        """(M,) bool per remaining photon: some part of the plant is above it."""
        s = self.state
        return s.canopy[s.photon_column] > s.photons.imag

    @property
    def descendants(self) -> np.ndarray:
        """(N,) number of nodes above each node in its plant; a read-only view."""
        view = self.state.descendants[1:self.state.n_nodes + 1]
        view.flags.writeable = False
        return view

    def tips(self) -> np.ndarray:
        """Indices of the branch tips (nodes without a child) of all plants."""
        return np.flatnonzero(~self.state.has_child[:self.state.n_nodes])

    def tip_positions(self) -> tuple[np.ndarray, ...]:
        """Per plant, the (K, 2) positions (x, z) in metres of its branch tips (read-only)."""
        if self._tips_cache is None:  # tips change only when the plant grows
            self._tips_cache = self._tip_positions()
        return self._tips_cache

    def _tip_positions(self) -> tuple[np.ndarray, ...]:
        tips = self.tips()
        xz = self.state.pos[tips].view(np.float64).reshape(-1, 2)  # complex = (x, z) pairs
        xz.flags.writeable = False
        if self.cfg.plant_count == 1:
            return (xz,)
        owner = self.state.plant[tips]
        per_plant = tuple(xz[owner == p] for p in range(self.cfg.plant_count))
        for array in per_plant:
            array.flags.writeable = False
        return per_plant

    def branch_counts(self) -> np.ndarray:
        """(n_plants,) segments per plant (the initial stem counts as one); a copy."""
        return self.state.branch_counts.copy()

    def thickness(self) -> np.ndarray:
        """(N,) thickness in metres of the segment ending at each node."""
        return self.thickness_for(self.descendants)

    def thickness_for(self, descendants: np.ndarray) -> np.ndarray:
        """Segment thickness (m) for descendant counts; the cube root keeps an 84 px trunk
        readable: a segment with 26 descendants is 3 times as thick as a twig."""
        return self.cfg.width_m(self.cfg.branch_thickness) * np.cbrt(1.0 + descendants)
