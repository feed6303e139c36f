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
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from growspace_sim.core import light as lights
from growspace_sim.core.config import SimConfig
from growspace_sim.core.tasks import distance_reward, draw_layout, jaccard

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

    Args:
        cfg: the validated configuration.
    """

    def __init__(self, cfg: SimConfig) -> None:
        self.cfg = cfg
        w = cfg.chamber_width
        self._res = cfg.resolution
        self._unit = cfg.width_m(cfg.target_radius)
        self._half_thickness = 0.5 * cfg.width_m(cfg.branch_thickness)
        self._influence = cfg.width_m(cfg.radius_of_influence)
        self._kill = cfg.width_m(cfg.kill_distance)
        self._branch_length = cfg.branch_length_m
        self._pixel = w / self._res  # m
        self._column_width = cfg.width_m(cfg.branch_thickness)  # m, shading resolution
        self._longest = max(cfg.branch_length_m, cfg.width_m(cfg.first_branch_height))
        self._sample_steps: dict[int, np.ndarray] = {}
        self._capacity = 2 * cfg.plant_count + cfg.max_branching * cfg.episode_length
        self._window = min(cfg.episode_length + 2, ANCESTOR_WINDOW)
        self.light: lights.Light | None = None
        self.steps = 0

    # ------------------------------------------------------------------ episode start
    def reset(self, rng: np.random.Generator, target_image: np.ndarray | None = None) -> None:
        """Begin an episode drawn from ``rng``.

        Args:
            rng: the episode's generator; layout and photons are drawn from it in a fixed order.
            target_image: the shape challenge's 28 x 28 digit (uint8, ink > 127 is the digit).

        Raises:
            ValueError: if the shape challenge gets no target image or one of the wrong shape.
        """
        cfg = self.cfg
        self._rng = rng
        layout = draw_layout(cfg, rng)
        n, cap = cfg.plant_count, self._capacity
        self.target = layout.target
        self.pos = np.zeros(cap, np.complex128)
        self.parent = np.full(cap, -1, np.int32)
        self.plant = np.zeros(cap, np.int16)
        self.has_child = np.zeros(cap, bool)
        self._descendants = np.zeros(cap + 1, np.int32)  # node i at i + 1; [0] counts blanks
        self._depth = np.zeros(cap, np.int32)
        # Row i lists 1 + node i's nearest ancestors (0 = none) at column depth % window, so
        # one bincount over the new rows updates the descendant counts along their paths.
        # np.zeros leaves untouched rows unmapped: memory grows with the nodes grown.
        self._ancestors = np.zeros((cap, self._window), np.int32)
        self.n_nodes = 0
        self._branch_counts = np.zeros(n, np.int64)
        self._nearest = np.full(n, np.inf)  # m, per plant: closest node to the target
        self.occupancy = np.zeros((self._res, self._res), bool)  # plant pixels (shape reward)
        self.target_mask = None
        if cfg.challenge == 'shape':
            self.target_mask = self._target_mask(target_image)
        self.light = lights.initial_light(cfg, layout.light_x, layout.light_z)
        self._canopy = np.zeros(int(math.ceil(cfg.chamber_width / self._column_width)))  # m
        roots = np.asarray(layout.stem_x, np.complex128)
        self.pos[:n] = roots  # roots have no parent and no segment
        self.plant[:n] = np.arange(n)
        self.n_nodes = n
        self._keep_photons(self._scatter_photons(rng))
        self._append(roots + 1j * cfg.width_m(cfg.first_branch_height), np.arange(n))
        self.steps = 0

    def set_photons(self, photons: np.ndarray) -> None:
        """Replace the photons (complex x + iz, m) of the current episode: crafted scenarios.

        Raises:
            ValueError: if a photon is not finite or lies outside the chamber.
        """
        photons = np.asarray(photons, np.complex128).reshape(-1)
        cfg = self.cfg
        bad = ~np.isfinite(photons) | (photons.real < 0) | (photons.real > cfg.chamber_width) \
            | (photons.imag < 0) | (photons.imag > cfg.chamber_height)
        if bad.any():
            raise ValueError(f'photon {photons[bad][0]!r} is not inside the chamber '
                             f'[0, {cfg.chamber_width}] x [0, {cfg.chamber_height}] m.')
        self._keep_photons(photons)

    def _keep_photons(self, photons: np.ndarray) -> None:
        """Store photons sorted by x (the photons of an x range are one slice) with their
        nearest node, which then only changes when a node grows closer."""
        self.photons = np.sort(photons)  # complex numbers sort by real part first
        self._photon_x = np.ascontiguousarray(self.photons.real)
        self._photon_column = self._column_of(self._photon_x)
        distances = np.abs(self.photons[:, None] - self.pos[:self.n_nodes])
        self._nearest_node = distances.argmin(axis=1)  # ties go to the older node
        self._nearest_distance = distances[np.arange(self.photons.size), self._nearest_node]
        self._refresh_available()

    def _refresh_available(self) -> None:
        """Flag the photons that would attract if lit: a node within reach, nothing above.

        Both only change when the plant grows, so a step without growth only slices this.
        """
        available = self._nearest_distance < self._influence
        if self.cfg.shading:
            available &= self._canopy[self._photon_column] <= self.photons.imag
        self._available = available

    def _x_range(self, low: float, high: float) -> slice:
        """The photons with low <= x <= high."""
        x = self._photon_x
        return slice(int(x.searchsorted(low, 'left')), int(x.searchsorted(high, 'right')))

    def _scatter_photons(self, rng: np.random.Generator) -> np.ndarray:
        cfg = self.cfg
        count = cfg.light_density
        x = rng.uniform(0.0, cfg.chamber_width, count)
        z = rng.uniform(cfg.photon_min_height * cfg.chamber_height, cfg.chamber_height, count)
        return x + 1j * z

    def _target_mask(self, image: np.ndarray | None) -> np.ndarray:
        if image is None:
            raise ValueError('the shape challenge needs a target_image (a 28 x 28 digit).')
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
        if self.light is None or self.steps >= self.cfg.episode_length:
            raise RuntimeError('the episode is over; call reset() first.')
        grown = self._grow()
        self.steps += 1
        return self._outcome(grown)

    def _grow(self) -> int:
        cfg, light = self.cfg, self.light
        half_span = light.radius if light.spot else 0.5 * light.width
        span = self._x_range(light.x - half_span, light.x + half_span)
        photons, distance = self.photons[span], self._nearest_distance[span]
        attracting = self._available[span]  # a view: read only
        if light.spot:
            attracting = attracting & (np.abs(photons - complex(light.x, light.z))
                                       <= light.radius)
        if not attracting.any():
            return 0
        nodes = self._nearest_node[span][attracting]
        pull = np.zeros(self.n_nodes, np.complex128)  # per node: sum of unit vectors
        np.add.at(pull, nodes, (photons[attracting] - self.pos[nodes]) / distance[attracting])
        strength = np.abs(pull)
        buds = np.flatnonzero(strength > _DIRECTION_EPS)
        if buds.size > cfg.max_branching:
            buds = np.sort(self._rng.choice(buds, cfg.max_branching, replace=False))
        new = self.pos[buds] + self._branch_length * pull[buds] / strength[buds]
        w, h = cfg.chamber_width, cfg.chamber_height
        inside = [0.0 <= p.real <= w and 0.0 <= p.imag <= h for p in new.tolist()]
        if not all(inside):  # a segment that would pierce a wall, floor or ceiling: not grown
            buds, new = buds[inside], new[inside]
            if buds.size == 0:
                return 0
        self._append(new, buds)
        return int(buds.size)

    def _append(self, new: np.ndarray, parents: np.ndarray) -> None:
        """Add nodes with segments to their parents and update what depends on them."""
        start, end = self.n_nodes, self.n_nodes + new.size
        self.n_nodes = end
        plants = self.plant[parents]
        self.pos[start:end] = new
        self.parent[start:end] = parents
        self.plant[start:end] = plants
        self.has_child[parents] = True
        self._branch_counts += np.bincount(plants, minlength=self._branch_counts.size)
        depth = self._depth[parents]
        self._depth[start:end] = depth + 1
        self._count_descendants(parents, depth, start, end)
        if self.target is not None:
            np.minimum.at(self._nearest, plants, np.abs(new - self.target))
        if self.target_mask is not None:
            self._rasterise(self._samples(self.pos[parents], new, 0.5 * self._pixel))
        self._update_photons(self.pos[parents], new, start)
        self._outcome_cache = self._tips_cache = None

    def _count_descendants(self, parents: np.ndarray, depth: np.ndarray, start: int,
                           end: int) -> None:
        """Give the new nodes start..end their ancestor rows and add one descendant to each
        of their ancestors.

        A row holds the ``window`` nearest ancestors; a node deeper than that reaches the rest
        through the row of its oldest listed ancestor, and so on up to the root.
        """
        window, table = self._window, self._ancestors
        ancestors = table[parents]
        ancestors[np.arange(parents.size), depth % window] = parents + 1
        table[start:end] = ancestors
        counts = np.bincount(ancestors.ravel(), minlength=end + 1)
        anchors = ancestors[depth >= window, (depth[depth >= window] + 1) % window] - 1
        while anchors.size:
            rows = table[anchors]
            counts += np.bincount(rows.ravel(), minlength=end + 1)
            deep = self._depth[anchors] > window
            anchors = rows[deep, self._depth[anchors][deep] % window] - 1
        self._descendants[:end + 1] += counts

    def _update_photons(self, a: np.ndarray, b: np.ndarray, first: int) -> None:
        """Re-point photons to the new nodes b (numbered from ``first``) where those are nearer,
        use up the photons at them and raise the canopy over the segments a-b."""
        distances = np.abs(self.photons[:, None] - b)
        closest = distances.argmin(axis=1)  # ties go to the older node, as argmin over all does
        distance = distances.min(axis=1)
        nearer = distance < self._nearest_distance
        self._nearest_node[nearer] = first + closest[nearer]
        self._nearest_distance[nearer] = distance[nearer]
        alive = distance >= self._kill
        if not alive.all():
            self.photons = self.photons[alive]
            self._photon_x = self._photon_x[alive]
            self._photon_column = self._photon_column[alive]
            self._nearest_node = self._nearest_node[alive]
            self._nearest_distance = self._nearest_distance[alive]
        self._shade(a, b)
        self._refresh_available()

    def _shade(self, a: np.ndarray, b: np.ndarray) -> None:
        """Raise the canopy (top of the plant per column) over the segments a-b.

        Columns are one branch thickness wide. Points sampled along each segment one column
        apart, each widened by half the thickness to both sides, mark every column the
        thickened segment covers, at the height of a point at most one column away.
        """
        points = self._samples(a, b, self._column_width)
        half = self._half_thickness
        columns = self._column_of(np.concatenate((points.real - half, points.real + half)))
        top = points.imag + half
        np.maximum.at(self._canopy, columns, np.concatenate((top, top)))

    def _column_of(self, x: np.ndarray) -> np.ndarray:
        column = (x * (1.0 / self._column_width)).astype(np.intp)
        return np.minimum(np.maximum(column, 0), self._canopy.size - 1)

    def _samples(self, a: np.ndarray, b: np.ndarray, spacing: float) -> np.ndarray:
        """Points along segments a-b (of at most one branch length), at most ``spacing`` apart."""
        count = int(self._longest / spacing) + 2
        t = self._sample_steps.get(count)
        if t is None:
            t = self._sample_steps[count] = np.linspace(0.0, 1.0, count)
        return (a[:, None] + (b - a)[:, None] * t).ravel()

    def _rasterise(self, points: np.ndarray) -> None:
        """Mark the image pixels that sampled segment points fall in (the plant's pixel set)."""
        res, cfg = self._res, self.cfg
        col = (points.real * (res / cfg.chamber_width)).astype(np.intp)
        row = ((cfg.chamber_height - points.imag) * (res / cfg.chamber_height)).astype(np.intp)
        self.occupancy[np.minimum(row, res - 1), np.minimum(col, res - 1)] = True

    def _outcome(self, grown: int) -> StepOutcome:
        if self._outcome_cache is None:  # the reward changes only when the plant grows
            self._outcome_cache = self._score()
        reward, plant_rewards, success = self._outcome_cache
        return StepOutcome(reward, plant_rewards.copy(), success,
                           self.steps >= self.cfg.episode_length, grown)

    def _score(self) -> tuple[float, np.ndarray, bool]:
        if self.target_mask is not None:
            reward = jaccard(self.occupancy, self.target_mask)
            return reward, np.array([reward]), reward >= self.cfg.shape_success
        plant_rewards = distance_reward(self._nearest, self._unit)
        reward = float(plant_rewards.min())  # one plant: its reward; fairness: the worst
        return reward, plant_rewards, reward >= 1.0

    # ------------------------------------------------------------------ views
    def current_reward(self) -> StepOutcome:
        """The reward of the current state, as a step would report it (used after reset)."""
        return self._outcome(0)

    @property
    def nodes(self) -> np.ndarray:
        """(N, 2) float64 node positions (x, z) in metres; a copy."""
        pos = self.pos[:self.n_nodes]
        return np.column_stack((pos.real, pos.imag))

    @property
    def shaded(self) -> np.ndarray:
        """(M,) bool per remaining photon: some part of the plant is above it."""
        return self._canopy[self._photon_column] > self.photons.imag

    @property
    def descendants(self) -> np.ndarray:
        """(N,) number of nodes above each node in its plant; a read-only view."""
        view = self._descendants[1:self.n_nodes + 1]
        view.flags.writeable = False
        return view

    def tips(self) -> np.ndarray:
        """Indices of the branch tips (nodes without a child) of all plants."""
        return np.flatnonzero(~self.has_child[:self.n_nodes])

    def tip_positions(self) -> tuple[np.ndarray, ...]:
        """Per plant, the (K, 2) positions (x, z) in metres of its branch tips (read-only)."""
        if self._tips_cache is None:  # tips change only when the plant grows
            self._tips_cache = self._tip_positions()
        return self._tips_cache

    def _tip_positions(self) -> tuple[np.ndarray, ...]:
        tips = self.tips()
        xz = self.pos[tips].view(np.float64).reshape(-1, 2)  # complex = (x, z) pairs in memory
        xz.flags.writeable = False
        if self.cfg.plant_count == 1:
            return (xz,)
        owner = self.plant[tips]
        per_plant = tuple(xz[owner == p] for p in range(self.cfg.plant_count))
        for array in per_plant:
            array.flags.writeable = False
        return per_plant

    def branch_counts(self) -> np.ndarray:
        """(n_plants,) segments per plant (the initial stem counts as one); a copy."""
        return self._branch_counts.copy()

    def thickness(self) -> np.ndarray:
        """(N,) thickness in metres of the segment ending at each node."""
        return self.thickness_for(self.descendants)

    def thickness_for(self, descendants: np.ndarray) -> np.ndarray:
        """Segment thickness (m) for descendant counts; the cube root keeps an 84 px trunk
        readable: a segment with 26 descendants is 3 times as thick as a twig."""
        return self.cfg.width_m(self.cfg.branch_thickness) * np.cbrt(1.0 + descendants)
