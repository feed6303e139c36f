"""The one typed configuration of a chamber; the only place where defaults live.

Geometry is in metres in the chamber frame: x along the light rail from the chamber's left wall,
z up from the floor. Growth parameters keep the paper's unit, a fraction of the chamber width
(GrowSpace appendix, table 'default parameters after performing a sweep'), so a plant looks the
same in any chamber size; the ``*_m`` properties turn them into metres.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from growspace_sim.core import task as tasks
from growspace_sim.core.task import SETTINGS, Task  # noqa: F401  (SETTINGS: re-exported)

REFERENCE_IMAGE_SIZE = 84  # px; the paper states light displacement in pixels of this image
# Bounds that keep an episode within a small machine (2 cores, 24 GB): memory grows linearly with
# the node slots (about 300 B each, chamber and renderer), the photons and the canopy columns.
MAX_NODES = 2_000_000  # node slots: max_branching x episode_length; about 600 MB at most
MIN_THICKNESS = 0.001  # fraction of the width: at most 1,000 canopy columns


@dataclass(frozen=True)
class Bounds:
    """The values a number field allows; also its ROS parameter's range.

    Attributes:
        low: Smallest value (excluded if ``low_open``).
        high: Largest value (included).
        integer: Only ints are allowed (else any finite number).
        low_open: ``low`` itself is not allowed (e.g. a fraction that must be positive).
        sentinel: One more allowed value outside ``[low, high]`` with a meaning of its own.
    """

    low: float
    high: float
    integer: bool = False
    low_open: bool = False
    sentinel: int | None = None

    def __str__(self) -> str:
        return f'{"]" if self.low_open else "["}{self.low}, {self.high}]'

    def check(self, name: str, value: object) -> None:
        """Raise ``ValueError`` naming the field, the value and what is allowed."""
        kind = int if self.integer else (int, float)
        if isinstance(value, bool) or not isinstance(value, kind):
            raise ValueError(f'{name} must be {"an int" if self.integer else "a number"}, '
                             f'got {value!r}.')
        if self.sentinel is not None and value == self.sentinel:
            return
        if not math.isfinite(value) or value > self.high or value < self.low \
                or (self.low_open and value == self.low):
            also = '' if self.sentinel is None else f' or {self.sentinel}'
            raise ValueError(f'{name} must be in {self}{also}, got {value!r}.')


_FRACTION = Bounds(0.0, 1.0, low_open=True)  # a positive fraction of the width or height
# The bounds of SimConfig's number fields: what __post_init__ checks and ROS parameters show.
BOUNDS = {
    'chamber_width': Bounds(0.01, 100.0), 'chamber_height': Bounds(0.01, 100.0),
    'image_size': Bounds(8, 1024, integer=True, sentinel=0),
    'episode_length': Bounds(1, 100_000, integer=True),
    'light_density': Bounds(1, 100_000, integer=True),
    'photon_min_height': _FRACTION, 'first_branch_height': _FRACTION,
    'branch_length': _FRACTION,
    # The canopy has one column per branch thickness: a floor keeps it small.
    'branch_thickness': Bounds(MIN_THICKNESS, 1.0),
    'max_branching': Bounds(1, 100, integer=True),
    'radius_of_influence': _FRACTION, 'kill_distance': _FRACTION, 'light_width': _FRACTION,
    'light_width_min': _FRACTION, 'light_width_max': _FRACTION,
    'light_step_px': Bounds(0.0, REFERENCE_IMAGE_SIZE, low_open=True),
    'spot_radius': _FRACTION, 'spot_radius_min': _FRACTION, 'spot_radius_max': _FRACTION,
    'target_radius': _FRACTION, 'n_plants': Bounds(1, 16, integer=True),
    'shape_success': _FRACTION,
}
# The rules that join fields, in words, by field (ROS shows them as additional constraints).
RULES = {
    **dict.fromkeys(('light_width_min', 'light_width', 'light_width_max'),
                    'light_width_min <= light_width <= light_width_max'),
    **dict.fromkeys(('spot_radius_min', 'spot_radius', 'spot_radius_max'),
                    'spot_radius_min <= spot_radius <= spot_radius_max'),
    **dict.fromkeys(('kill_distance', 'radius_of_influence'),
                    'kill_distance < radius_of_influence'),
    **dict.fromkeys(('first_branch_height', 'chamber_height'),
                    'first_branch_height x chamber_width < chamber_height'),
    **dict.fromkeys(('max_branching', 'episode_length'),
                    f'max_branching x episode_length <= {MAX_NODES}'),
    'image_size': "0 = the challenge's default (84, or 28 for shape)",
    'digits': "each 0..9; empty = the setting's digit (easy 3, hard 0)",
}


def choices(name: str) -> tuple[str, ...]:
    """The allowed values of a string field of SimConfig (empty for other fields)."""
    return {'challenge': tasks.names(), 'setting': SETTINGS}.get(name, ())


@dataclass(frozen=True)
class SimConfig:
    """Everything that defines a chamber run, validated on construction.

    Every field is a ROS parameter of ``sim_node`` with the same name (``config/growspace.yaml``).
    Integer fields that ROS cannot leave unset use a documented sentinel (``0`` or ``-1``).
    """

    challenge: str = 'control'  # one of CHALLENGES
    setting: str = 'easy'  # one of SETTINGS
    chamber_width: float = 0.84  # m; 1 cm per pixel of the 84 px image
    chamber_height: float = 0.84  # m
    image_size: int = 0  # px, square; 0 = challenge default (84, or 28 for shape)
    episode_length: int = 50  # steps; the episode is truncated (not terminated) after it
    light_density: int = 200  # photons scattered per episode
    photon_min_height: float = 0.25  # fraction of the height; photons lie above it
    first_branch_height: float = 0.2  # fraction of the width; length of the initial stem
    branch_length: float = 0.1  # fraction of the width; length of every new segment
    branch_thickness: float = 0.015  # fraction of the width; thickness of a segment with no child
    max_branching: int = 8  # new segments per step at most, over all plants
    radius_of_influence: float = 0.15  # fraction of the width; photons farther do not attract
    kill_distance: float = 0.05  # fraction of the width; photons closer to the plant are used up
    light_width: float = 0.25  # fraction of the width; initial beam width
    light_width_min: float = 0.1  # fraction of the width
    light_width_max: float = 0.5  # fraction of the width
    light_step_px: float = 5.0  # px of the 84 px reference image; light move per action
    spot_radius: float = 0.1  # fraction of the width; initial spotlight radius
    spot_radius_min: float = 0.05  # fraction of the width
    spot_radius_max: float = 0.3  # fraction of the width
    shading: bool = True  # photons under the plant's foliage are not lit
    target_radius: float = 0.03  # fraction of the width; the reward's distance unit (see tasks)
    n_plants: int = 2  # plants in the fairness challenge (n > 1); the others grow one
    digits: tuple[int, ...] = ()  # shape targets drawn from these; () = setting (easy 3, hard 0)
    shape_success: float = 0.5  # Jaccard index at which the shape counts as reached

    def __post_init__(self) -> None:
        if not isinstance(self.challenge, str):
            raise ValueError(f'challenge must be one of {tasks.names()}, got {self.challenge!r}.')
        task = tasks.get(self.challenge)
        _check_choice('setting', self.setting, task.settings)
        for name, bounds in BOUNDS.items():
            bounds.check(name, getattr(self, name))
        if self.max_branching * self.episode_length > MAX_NODES:
            raise ValueError(
                f'max_branching x episode_length ({self.max_branching} x {self.episode_length}'
                f' = {self.max_branching * self.episode_length}) must be in [1, {MAX_NODES}]: '
                f'the chamber keeps room for every node an episode can grow.')
        if not isinstance(self.shading, bool):
            raise ValueError(f'shading must be a bool, got {self.shading!r}.')
        _check_order('light_width_min', self.light_width_min, 'light_width',
                     self.light_width, 'light_width_max', self.light_width_max)
        _check_order('spot_radius_min', self.spot_radius_min, 'spot_radius',
                     self.spot_radius, 'spot_radius_max', self.spot_radius_max)
        if self.kill_distance >= self.radius_of_influence:
            raise ValueError(
                f'kill_distance ({self.kill_distance}) must be lower than radius_of_influence '
                f'({self.radius_of_influence}), or no photon could ever attract the plant.')
        if self.first_branch_height * self.chamber_width >= self.chamber_height:
            raise ValueError(
                f'first_branch_height ({self.first_branch_height} of the width) must end below '
                f'the chamber top ({self.chamber_height} m).')
        if not isinstance(self.digits, tuple) or not all(
                isinstance(d, int) and not isinstance(d, bool) and 0 <= d <= 9
                for d in self.digits):
            raise ValueError(f'digits must be a tuple of ints in 0..9, got {self.digits!r}.')
        if task.multi_plant and self.n_plants < 2:
            raise ValueError(f'n_plants must be at least 2 for {task.name}, got {self.n_plants}.')

    @classmethod
    def from_dict(cls, values: dict) -> SimConfig:
        """Build a config from a mapping (a ROS parameter dict), rejecting unknown keys.

        Raises:
            ValueError: on an unknown key or an invalid value.
        """
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f'Unknown parameter(s) {unknown}; allowed: {sorted(known)}.')
        values = dict(values)
        if 'digits' in values:
            values['digits'] = tuple(int(d) for d in values['digits'])
        return cls(**values)

    def replace(self, **changes) -> SimConfig:
        """Return a validated copy with some fields changed."""
        return dataclasses.replace(self, **changes)

    # Derived quantities live in properties so they can never drift from their source.
    @property
    def task(self) -> Task:
        """The challenge's ``Task``: what differs between challenges."""
        return tasks.get(self.challenge)

    @property
    def uses_spotlight(self) -> bool:
        return self.task.spotlight

    @property
    def plant_count(self) -> int:
        """Plants that grow: ``n_plants`` in a multi-plant challenge, else one."""
        return self.n_plants if self.task.multi_plant else 1

    @property
    def resolution(self) -> int:
        """Observation side in pixels."""
        return self.image_size or self.task.resolution

    @property
    def target_digits(self) -> tuple[int, ...]:
        """The digits shape targets are drawn from; () for a task with a point target."""
        if self.digits or self.task.digits is None:
            return self.digits
        return self.task.digits[self.setting]

    @property
    def branch_length_m(self) -> float:
        return self.branch_length * self.chamber_width

    @property
    def light_step_m(self) -> float:
        return self.light_step_px / REFERENCE_IMAGE_SIZE * self.chamber_width

    def width_m(self, fraction: float) -> float:
        """A fraction of the chamber width, in metres."""
        return fraction * self.chamber_width


def _check_choice(name: str, value: object, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ValueError(f'{name} must be one of {allowed}, got {value!r}.')


def _check_order(low_name: str, low: float, mid_name: str, mid: float, high_name: str,
                 high: float) -> None:
    if not low <= mid <= high:
        raise ValueError(
            f'{low_name} ({low}) <= {mid_name} ({mid}) <= {high_name} ({high}) must hold.')
