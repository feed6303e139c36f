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
challenge's ``Task`` (``cfg.task``) decides the layout and the reward.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from growspace_sim.core import light as lights
from growspace_sim.core.config import SimConfig
from growspace_sim.core.state import ChamberState

_DIRECTION_EPS = 1e-12  # a sum of unit vectors this short has no direction: the bud stays
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
        self._sample_steps: dict[int, np.ndarray] = {}
        self._capacity = 2 * cfg.plant_count + cfg.max_branching * cfg.episode_length
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

        Both only change when the plant grows, so a step without growth only slices this.
        """
        available = distance < self._influence
        if self.cfg.shading:
            available &= canopy[column] <= photons.imag
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
        cfg, light = self.cfg, s.light
        half_span = light.radius if light.spot else 0.5 * light.width
        x = s.photon_x
        span = slice(int(x.searchsorted(light.x - half_span, 'left')),
                     int(x.searchsorted(light.x + half_span, 'right')))
        photons, distance = s.photons[span], s.nearest_distance[span]
        attracting = s.available[span]  # a view: read only
        if light.spot:
            attracting = attracting & (np.abs(photons - complex(light.x, light.z))
                                       <= light.radius)
        if not attracting.any():
            return 0
        nodes = s.nearest_node[span][attracting]
        pull = np.zeros(s.n_nodes, np.complex128)  # per node: sum of unit vectors
        np.add.at(pull, nodes, (photons[attracting] - s.pos[nodes]) / distance[attracting])
        strength = np.abs(pull)
        buds = np.flatnonzero(strength > _DIRECTION_EPS)
        if buds.size > cfg.max_branching:
            buds = np.sort(s.rng.choice(buds, cfg.max_branching, replace=False))
        new = s.pos[buds] + self._branch_length * pull[buds] / strength[buds]
        w, h = cfg.chamber_width, cfg.chamber_height
        inside = [0.0 <= p.real <= w and 0.0 <= p.imag <= h for p in new.tolist()]
        if not all(inside):  # a segment that would pierce a wall, floor or ceiling: not grown
            buds, new = buds[inside], new[inside]
            if buds.size == 0:
                return 0
        self._append(s, new, buds)
        return int(buds.size)

    def _append(self, s: ChamberState, new: np.ndarray, parents: np.ndarray) -> None:
        """Add nodes with segments to their parents and update what depends on them."""
        start, end = s.n_nodes, s.n_nodes + new.size
        s.n_nodes = end
        plants = s.plant[parents]
        s.pos[start:end] = new
        s.parent[start:end] = parents
        s.plant[start:end] = plants
        s.has_child[parents] = True
        s.branch_counts += np.bincount(plants, minlength=s.branch_counts.size)
        depth = s.depth[parents]
        s.depth[start:end] = depth + 1
        self._count_descendants(s, parents, depth, start, end)
        if s.target is not None:
            np.minimum.at(s.nearest, plants, np.abs(new - s.target))
        if s.target_mask is not None:
            self._rasterise(s, self._samples(s.pos[parents], new, 0.5 * self._pixel))
        self._update_photons(s, s.pos[parents], new, start)
        self._outcome_cache = self._tips_cache = None

    def _count_descendants(self, s: ChamberState, parents: np.ndarray, depth: np.ndarray,
                           start: int, end: int) -> None:
        """Give the new nodes start..end their ancestor rows and add one descendant to each
        of their ancestors.

        A row holds the ``window`` nearest ancestors; a node deeper than that reaches the rest
        through the row of its oldest listed ancestor, and so on up to the root.
        """
        window, table = self._window, s.ancestors
        ancestors = table[parents]
        if not self._deep:  # episodes shorter than the window: every row lists all ancestors
            ancestors[np.arange(parents.size), depth] = parents + 1
            table[start:end] = ancestors
            s.descendants[:end + 1] += np.bincount(ancestors.ravel(), minlength=end + 1)
            return
        ancestors[np.arange(parents.size), depth % window] = parents + 1
        table[start:end] = ancestors
        counts = np.bincount(ancestors.ravel(), minlength=end + 1)
        incomplete = depth >= window
        anchors = ancestors[incomplete, (depth[incomplete] + 1) % window] - 1
        while anchors.size:
            rows = table[anchors]
            counts += np.bincount(rows.ravel(), minlength=end + 1)
            anchor_depth = s.depth[anchors]
            incomplete = anchor_depth > window
            anchors = rows[incomplete, anchor_depth[incomplete] % window] - 1
        s.descendants[:end + 1] += counts

    def _update_photons(self, s: ChamberState, a: np.ndarray, b: np.ndarray,
                        first: int) -> None:
        """Re-point photons to the new nodes b (numbered from ``first``) where those are nearer,
        use up the photons at them and raise the canopy over the segments a-b."""
        distances = np.abs(s.photons[:, None] - b)
        closest = distances.argmin(axis=1)  # ties go to the older node, as argmin over all does
        distance = distances.min(axis=1)
        nearer = distance < s.nearest_distance
        s.nearest_node[nearer] = first + closest[nearer]
        s.nearest_distance[nearer] = distance[nearer]
        alive = distance >= self._kill
        if not alive.all():
            s.photons = s.photons[alive]
            s.photon_x = s.photon_x[alive]
            s.photon_column = s.photon_column[alive]
            s.nearest_node = s.nearest_node[alive]
            s.nearest_distance = s.nearest_distance[alive]
        self._shade(s.canopy, a, b)
        s.available = self._available(s.nearest_distance, s.canopy, s.photon_column, s.photons)

    def _shade(self, canopy: np.ndarray, a: np.ndarray, b: np.ndarray) -> None:
        """Raise the canopy (top of the plant per column) over the segments a-b.

        Columns are one branch thickness wide. Points sampled along each segment one column
        apart, each widened by half the thickness to both sides, mark every column the
        thickened segment covers, at the height of a point at most one column away.
        """
        points = self._samples(a, b, self._column_width)
        half = self._half_thickness
        columns = self._column_of(np.concatenate((points.real - half, points.real + half)))
        top = points.imag + half
        np.maximum.at(canopy, columns, np.concatenate((top, top)))

    def _column_of(self, x: np.ndarray) -> np.ndarray:
        column = (x * (1.0 / self._column_width)).astype(np.intp)
        return np.minimum(np.maximum(column, 0), self._columns - 1)

    def _samples(self, a: np.ndarray, b: np.ndarray, spacing: float) -> np.ndarray:
        """Points along segments a-b (of at most one branch length), at most ``spacing`` apart."""
        count = int(self._longest / spacing) + 2
        t = self._sample_steps.get(count)
        if t is None:
            t = self._sample_steps[count] = np.linspace(0.0, 1.0, count)
        return (a[:, None] + (b - a)[:, None] * t).ravel()

    def _rasterise(self, s: ChamberState, points: np.ndarray) -> None:
        """Mark the image pixels that sampled segment points fall in (the plant's pixel set)."""
        res, cfg = self._res, self.cfg
        col = (points.real * (res / cfg.chamber_width)).astype(np.intp)
        row = ((cfg.chamber_height - points.imag) * (res / cfg.chamber_height)).astype(np.intp)
        s.occupancy[np.minimum(row, res - 1), np.minimum(col, res - 1)] = True

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
        """(M,) complex128 remaining photons (m), sorted by x."""
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
