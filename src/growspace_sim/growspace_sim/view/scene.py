"""A chamber's topics gathered into one ``Frame`` per tick: what the markers and image show.

The state topics carry the plant and the light but not the target or the photons. Those come
from ``chamber/config`` (latched, republished at every reset with the effective parameters and
the seed): a ``Simulation`` rebuilt from that config and seed and reset has the episode's target
and start photons, without the chamber sending anything new. The scene keeps that simulation in
step by placing each tick's ``light/state`` (the applied, absolute light) and stepping, as
replay's re-simulation does, and checks after every tick that its plant equals ``plant/state``
bit for bit. Photons are shown only while it does; after a mismatch, a config without a seed
that cannot continue a synced stream, a view that joined mid-episode, or ``"source": "gantry"``
(a real plant: simulated photons would mean nothing), the frame has no photons. The target
needs no stepping, so it is known whenever the episode's config and seed are.

Messages arrive on four topics whose callbacks may interleave, so plant and light states are
matched to the ``step_result`` (the last message of a tick) by their common header stamp.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import math
from typing import Any

import numpy as np

from growspace_sim.core.config import SimConfig
from growspace_sim.ros import convert
from growspace_sim.simulation import Simulation

_KEEP = 16  # plant and light states kept while waiting for their step_result
MAX_PLANTS = 16  # SimConfig.n_plants' upper bound


class ViewInputError(ValueError):
    """A message the view cannot use; names the topic, the field and its value.

    Args:
        topic: e.g. ``plant/state``.
        field: the offending field.
        value: its value (shortened in the text).
        allowed: what would have been accepted.
    """

    def __init__(self, topic: str, field: str, value: Any, allowed: str) -> None:
        self.topic, self.field, self.value = topic, field, value
        text = repr(value)
        if len(text) > 80:
            text = text[:77] + '...'
        super().__init__(f'{topic}: {field} = {text}, expected {allowed}; message ignored.')


@dataclasses.dataclass(frozen=True)
class Frame:
    """Everything one view of a tick shows; positions in metres, chamber frame (x, z)."""

    cfg: SimConfig  # the episode's configuration (defaults until a config arrives)
    stamp_ns: int  # header stamp of the tick [ns]
    step: int  # step index within the episode, 0 right after a reset
    reward: float  # reward of the tick [1]
    plant_rewards: np.ndarray  # (n_plants,) float64 [1]
    node_x: np.ndarray  # (N,) float64 [m]
    node_z: np.ndarray  # (N,) float64 [m]
    parent: np.ndarray  # (N,) int32, -1 for a root
    plant: np.ndarray  # (N,) uint8 plant of each node
    thickness: np.ndarray  # (N,) float64 thickness of the segment ending at each node [m]
    light: Any | None  # the applied LightCommand (MODE_BEAM / MODE_SPOT), None if unknown
    target: complex | None  # point target x + iz [m], None if unknown or a shape
    target_mask: np.ndarray | None  # (res, res) bool digit pixels of a shape target
    photons: np.ndarray | None  # (M,) complex128 x + iz [m], None when not known
    lit: np.ndarray | None  # (M,) bool, photons the light reaches and nothing shades

    @property
    def reset(self) -> bool:
        """True for the first frame of an episode (markers start with DELETEALL)."""
        return self.step == 0


def descendants(parent: np.ndarray) -> np.ndarray:
    """Nodes above each node in its plant (parents come before their children).

    Args:
        parent: (N,) parent index of each node, -1 for a root, ``parent[i] < i``.

    Returns:
        (N,) int64 counts.
    """
    count = np.zeros(parent.size + 1, np.int64)  # slot N absorbs the roots' -1
    for i, p in zip(range(parent.size - 1, -1, -1), parent[::-1].tolist()):
        count[p] += count[i] + 1
    return count[:parent.size]


class Scene:
    """Collects a chamber's topics; ``on_result`` gives the frame of each tick.

    Every ``on_*`` method raises ``ViewInputError`` for a message it cannot use and then leaves
    the scene as it was, so the caller only logs it.
    """

    def __init__(self) -> None:
        self.cfg = SimConfig()
        self.source = 'sim'
        self.frame_id = 'chamber'  # of the chamber's headers, from the config
        self.image_frame_id = 'chamber_camera'  # of its camera images, from the config
        self.sim: Simulation | None = None
        self.target: complex | None = None  # of the episode, kept when the re-simulation stops
        self.target_mask: np.ndarray | None = None
        self.synced = False  # the re-simulation's plant equals the latest plant/state
        self.note = 'no chamber/config yet'  # why photons are not shown, for the log
        self._plants: collections.OrderedDict[int, Any] = collections.OrderedDict()
        self._lights: collections.OrderedDict[int, Any] = collections.OrderedDict()
        self._plant: Any | None = None
        self._light: Any | None = None

    # --- inputs --------------------------------------------------------------------------

    def on_config(self, text: str) -> None:
        """A ``chamber/config`` payload: the new episode's configuration and seed.

        Raises:
            ViewInputError: not JSON, no valid ``config``.
        """
        try:
            payload = json.loads(text)
        except ValueError:
            raise ViewInputError('chamber/config', 'data', text, 'JSON') from None
        if not isinstance(payload, dict) or not isinstance(payload.get('config'), dict):
            raise ViewInputError('chamber/config', 'data', text, 'a JSON object with "config"')
        try:
            cfg = SimConfig.from_dict(payload['config'])
        except (ValueError, TypeError) as e:
            raise ViewInputError('chamber/config', 'config', payload['config'],
                                 f'valid SimConfig fields ({e})') from None
        seed = payload.get('seed')
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)
                                 or not 0 <= seed <= convert.MAX_SEED):
            raise ViewInputError('chamber/config', 'seed', seed, 'null or an int >= 0')
        self.cfg, self.source = cfg, str(payload.get('source', 'sim'))
        self.frame_id = str(payload.get('frame_id') or self.frame_id)
        self.image_frame_id = str(payload.get('image_frame_id') or self.image_frame_id)
        self._restart(cfg, seed, str(payload.get('digit_source', 'auto')))

    def _restart(self, cfg: SimConfig, seed: int | None, digit_source: str) -> None:
        previous, self.sim, self.synced = (self.sim if self.synced else None), None, False
        self.target = self.target_mask = None
        try:
            if seed is not None:
                sim = Simulation(cfg, digit_source)
            elif previous is not None:  # the node continued its stream: so do we
                sim = previous if cfg == previous.cfg else previous.with_config(cfg)
            else:
                self.note = 'unseeded reset of a stream the view did not follow'
                return
            sim.reset(seed=seed)
        except (ValueError, FileNotFoundError, OSError) as e:  # e.g. no digit set here
            self.note = f'cannot re-simulate the episode: {e}'
            return
        self.sim, self.note = sim, ''
        self.target, self.target_mask = sim.chamber.target, sim.chamber.target_mask

    def on_plant(self, msg: Any) -> None:
        """A ``growspace_msgs/PlantState``.

        Raises:
            ViewInputError: arrays of different lengths, non-finite or out-of-chamber nodes,
                a parent that is not an earlier node, a plant index out of range.
        """
        n = len(msg.node_x)
        for name in ('node_z', 'parent', 'plant'):
            if len(getattr(msg, name)) != n:
                raise ViewInputError('plant/state', f'len({name})', len(getattr(msg, name)),
                                     f'{n} (= len(node_x))')
        x, z = np.asarray(msg.node_x, np.float64), np.asarray(msg.node_z, np.float64)
        for name, values in (('node_x', x), ('node_z', z)):
            bad = ~np.isfinite(values)
            if bad.any():
                raise ViewInputError('plant/state', name, float(values[bad][0]),
                                     'finite numbers [m]')
        parent = np.asarray(msg.parent, np.int64)
        bad = (parent < -1) | (parent >= np.arange(n))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ViewInputError('plant/state', f'parent[{i}]', int(parent[i]),
                                 f'-1 or an index below {i}')
        plant = np.asarray(msg.plant, np.int64)
        if n and plant.max() >= MAX_PLANTS:
            raise ViewInputError('plant/state', 'plant', int(plant.max()),
                                 f'indices below {MAX_PLANTS}')
        self._plant = msg
        _keep(self._plants, convert.to_ns(msg.header.stamp), msg)

    def on_light(self, msg: Any) -> None:
        """A ``light/state`` (``growspace_msgs/LightCommand`` in MODE_BEAM or MODE_SPOT).

        Raises:
            ViewInputError: another mode or a non-finite coordinate.
        """
        if int(msg.mode) not in (convert.MODE_BEAM, convert.MODE_SPOT):
            raise ViewInputError('light/state', 'mode', int(msg.mode),
                                 f'{convert.MODE_BEAM} (beam) or {convert.MODE_SPOT} (spot)')
        for name in ('x', 'z', 'width', 'radius'):
            value = float(getattr(msg, name))
            if not math.isfinite(value) or value < 0.0 and name in ('width', 'radius'):
                raise ViewInputError('light/state', name, value, 'a finite number [m]')
        self._light = msg
        _keep(self._lights, convert.to_ns(msg.header.stamp), msg)

    def on_result(self, msg: Any) -> Frame:
        """A ``step_result``, the last message of a tick: advance and return its frame.

        Raises:
            ViewInputError: a non-finite reward.
        """
        reward = float(msg.reward)
        rewards = np.asarray(msg.plant_rewards, np.float64)
        if not math.isfinite(reward) or not np.isfinite(rewards).all():
            raise ViewInputError('step_result', 'reward', reward, 'finite numbers')
        stamp = convert.to_ns(msg.header.stamp)
        plant = self._plants.get(stamp, self._plant)
        light = self._lights.get(stamp, self._light)
        step = int(msg.step)
        self._advance(step, plant, light)
        return self._frame(stamp, step, reward, rewards, plant, light)

    # --- the re-simulation ---------------------------------------------------------------

    def _advance(self, step: int, plant: Any | None, light: Any | None) -> None:
        sim = self.sim
        if sim is None:
            return
        steps = sim.chamber.steps
        try:
            if step == steps + 1 and light is not None and step <= sim.cfg.episode_length:
                sim.place_light(float(light.x), float(light.z), float(light.width),
                                float(light.radius))
                sim.step()
            elif step != steps:  # a tick the view missed (joined late, lost a message)
                raise ValueError(f'step {step} after re-simulated step {steps}')
        except Exception as e:  # noqa: BLE001 - any failure only means: no photons
            self._desync(f'{e}')
            return
        if plant is None or not self._same_plant(plant):
            self._desync(f'the re-simulated plant differs from plant/state at step {step}')
            return
        self.synced = True

    def _same_plant(self, msg: Any) -> bool:
        chamber = self.sim.chamber
        pos = chamber.pos[:chamber.n_nodes]
        return (len(msg.node_x) == pos.size and np.array_equal(msg.node_x, pos.real)
                and np.array_equal(msg.node_z, pos.imag))

    def _desync(self, why: str) -> None:
        self.sim, self.synced = None, False
        self.note = why

    # --- frames --------------------------------------------------------------------------

    def _frame(self, stamp: int, step: int, reward: float, rewards: np.ndarray,
               plant: Any | None, light: Any | None) -> Frame:
        cfg = self.cfg
        if plant is None:
            x = z = np.zeros(0)
            parent, owner = np.zeros(0, np.int32), np.zeros(0, np.uint8)
        else:
            x, z = np.asarray(plant.node_x, np.float64), np.asarray(plant.node_z, np.float64)
            parent = np.asarray(plant.parent, np.int32)
            owner = np.asarray(plant.plant, np.uint8)
        thickness = cfg.width_m(cfg.branch_thickness) * np.cbrt(1.0 + descendants(parent))
        photons = lit = None
        sim = self.sim
        if sim is not None:
            chamber = sim.chamber
            if self.synced and self.source != 'gantry':
                photons = chamber.photons.copy()
                lit = _lit(photons, chamber.light) & ~chamber.shaded if cfg.shading \
                    else _lit(photons, chamber.light)
        return Frame(cfg=cfg, stamp_ns=stamp, step=step, reward=reward, plant_rewards=rewards,
                     node_x=x, node_z=z, parent=parent, plant=owner, thickness=thickness,
                     light=light, target=self.target, target_mask=self.target_mask,
                     photons=photons, lit=lit)


def _lit(photons: np.ndarray, light: Any) -> np.ndarray:
    """Photons inside the beam's columns or the spotlight's disc (``Chamber.step``'s rule)."""
    if light.spot:
        return np.abs(photons - complex(light.x, light.z)) <= light.radius
    return np.abs(photons.real - light.x) <= 0.5 * light.width


def _keep(store: collections.OrderedDict, stamp: int, msg: Any) -> None:
    store[stamp] = msg
    store.move_to_end(stamp)
    while len(store) > _KEEP:
        store.popitem(last=False)
