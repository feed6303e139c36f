"""The chamber light: a vertical beam or a circular spotlight, its actions and its clamping.

The light is always inside the chamber: a beam spans ``[x - width/2, x + width/2]`` within the
walls, a spotlight's disc lies within the walls, floor and ceiling. Every way of moving it ends in
``clamp``, so RL actions, absolute commands from ROS and a future LED gantry share one rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from growspace_sim.core.config import SimConfig
from growspace_sim.core.errors import CommandError

BEAM_ACTIONS = ('left', 'right', 'stay', 'wider', 'narrower')
SPOT_ACTIONS = ('left', 'right', 'up', 'down', 'bigger', 'smaller', 'stay')
# What each discrete action changes, and by how many light steps (None: nothing).
MOVES = {
    'left': ('x', -1.0), 'right': ('x', 1.0), 'up': ('z', 1.0), 'down': ('z', -1.0),
    'wider': ('width', 1.0), 'narrower': ('width', -1.0),
    'bigger': ('radius', 0.5), 'smaller': ('radius', -0.5), 'stay': None,
}


@dataclass
class Light:
    """Where the light is, in metres in the chamber frame."""

    spot: bool  # True: circular spotlight (x, z, radius); False: vertical beam (x, width)
    x: float  # m, centre along the rail
    z: float  # m, spotlight centre height (unused by the beam)
    width: float  # m, beam width (unused by the spotlight)
    radius: float  # m, spotlight radius (unused by the beam)

    def copy(self) -> Light:
        return Light(self.spot, self.x, self.z, self.width, self.radius)


def initial_light(cfg: SimConfig, x: float, z: float) -> Light:
    """A light of the configured initial size centred at (x, z), clamped into the chamber."""
    light = Light(cfg.uses_spotlight, x, z, cfg.width_m(cfg.light_width),
                  cfg.width_m(cfg.spot_radius))
    clamp(light, cfg)
    return light


def clamp(light: Light, cfg: SimConfig) -> None:
    """Bring the light back inside its limits."""
    w, h = cfg.chamber_width, cfg.chamber_height
    if light.spot:
        light.radius = _clip(light.radius, cfg.width_m(cfg.spot_radius_min),
                             cfg.width_m(cfg.spot_radius_max))
        light.x = _clip(light.x, light.radius, w - light.radius)
        light.z = _clip(light.z, light.radius, h - light.radius)
    else:
        light.width = _clip(light.width, cfg.width_m(cfg.light_width_min),
                            cfg.width_m(cfg.light_width_max))
        half = 0.5 * light.width
        light.x = _clip(light.x, half, w - half)


def apply_discrete(light: Light, action: int, cfg: SimConfig) -> None:
    """Move or resize the light by one discrete action (BEAM_ACTIONS or SPOT_ACTIONS).

    Raises:
        CommandError: if ``action`` is not an index of the light's action list.
    """
    names = SPOT_ACTIONS if light.spot else BEAM_ACTIONS
    if isinstance(action, bool) or not isinstance(action, (int, np.integer)) \
            or not 0 <= action < len(names):
        raise CommandError('action', action,
                           f'an int in [0, {len(names) - 1}] ({", ".join(names)})')
    move = MOVES[names[action]]
    if move is not None:
        field, light_steps = move
        setattr(light, field, getattr(light, field) + light_steps * cfg.light_step_m)
    clamp(light, cfg)


def continuous_size(light: Light) -> int:
    """Length of the continuous action vector: (velocity, width) or (dx, dz, radius)."""
    return 3 if light.spot else 2


def apply_continuous(light: Light, action: np.ndarray, cfg: SimConfig) -> None:
    """Apply a continuous action, every component in [-1, 1].

    Beam: ``(velocity, width)``; velocity 1 moves one light step right, width maps [-1, 1]
    linearly onto [light_width_min, light_width_max]. Spotlight: ``(dx, dz, radius)`` with dx and
    dz in light steps and radius mapped onto [spot_radius_min, spot_radius_max].

    Raises:
        CommandError: on a wrong length or a value that is not finite or outside [-1, 1].
    """
    size = continuous_size(light)
    values = np.asarray(action, dtype=np.float64).reshape(-1)
    if values.size != size:
        # A huge vector is quoted as numpy summarises it, not as a list of every value.
        raise CommandError('continuous', values.tolist() if values.size <= 16 else values,
                           f'{size} values in [-1, 1], not {values.size}')
    finite = np.isfinite(values)
    bad = ~finite | (np.abs(np.where(finite, values, 0.0)) > 1.0)  # no NaN comparison warnings
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise CommandError(f'continuous[{i}]', float(values[i]), 'a finite number in [-1, 1]')
    step = cfg.light_step_m
    light.x += float(values[0]) * step
    if light.spot:
        light.z += float(values[1]) * step
        light.radius = _lerp(cfg.width_m(cfg.spot_radius_min),
                             cfg.width_m(cfg.spot_radius_max), float(values[2]))
    else:
        light.width = _lerp(cfg.width_m(cfg.light_width_min),
                            cfg.width_m(cfg.light_width_max), float(values[1]))
    clamp(light, cfg)


def set_absolute(light: Light, cfg: SimConfig, x: float, z: float, width: float,
                 radius: float) -> None:
    """Place the light at absolute coordinates (m), as an LED gantry would be commanded.

    Raises:
        CommandError: naming the first coordinate that is not finite.
    """
    for name, value in (('x', x), ('z', z), ('width', width), ('radius', radius)):
        if not math.isfinite(value):
            raise CommandError(name, value, 'a finite number [m]')
    light.x, light.z, light.width, light.radius = x, z, width, radius
    clamp(light, cfg)


def _clip(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


def _lerp(low: float, high: float, unit: float) -> float:
    return low + 0.5 * (unit + 1.0) * (high - low)
