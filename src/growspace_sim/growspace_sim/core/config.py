"""The one typed configuration of a chamber; the only place where defaults live.

Geometry is in metres in the chamber frame: x along the light rail from the chamber's left wall,
z up from the floor. Growth parameters keep the paper's unit, a fraction of the chamber width
(GrowSpace appendix, table 'default parameters after performing a sweep'), so a plant looks the
same in any chamber size; the ``*_m`` properties turn them into metres.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from growspace_sim.core import task as tasks
from growspace_sim.core.errors import echo
from growspace_sim.core.schema import AT_RESET, Bounds, check, param
from growspace_sim.core.task import SETTINGS, Task

REFERENCE_IMAGE_SIZE = 84  # px; the paper states light displacement in pixels of this image
# Bounds that keep an episode within a small machine (2 cores, 24 GB): memory grows linearly with
# the node slots (about 300 B each, chamber and renderer), the photons and the canopy columns.
MAX_NODES = 2_000_000  # node slots: max_branching x episode_length; about 600 MB at most
MIN_THICKNESS = 0.001  # fraction of the width: at most 1,000 canopy columns
WIDTH, HEIGHT = 'fraction of the width', 'fraction of the height'
_FRACTION = Bounds(0.0, 1.0, low_open=True)  # a positive fraction of the width or height
_WIDTH_ORDER = 'light_width_min <= light_width <= light_width_max'
_SPOT_ORDER = 'spot_radius_min <= spot_radius <= spot_radius_max'
_KILL = 'kill_distance < radius_of_influence'
_STEM = 'first_branch_height x chamber_width < chamber_height'
_NODES = f'max_branching x episode_length <= {MAX_NODES}'


def _fraction(default: float, doc: str, unit: str = WIDTH, rule: str = '') -> float:
    return param(default, doc, unit=unit, bounds=_FRACTION, rule=rule, when=AT_RESET)


@dataclass(frozen=True)
class SimConfig:
    """Everything that defines a chamber run, validated on construction.

    Every field is a ROS parameter of ``sim_node`` with the same name (``config/growspace.yaml``),
    declared once here (``core.schema``): meaning, unit, range and rules. Integer fields that
    ROS cannot leave unset use a documented sentinel (``0`` or ``-1``).
    """

    challenge: str = param(
        'control', 'the challenge', choices=tasks.names, accept=tasks.get, when=AT_RESET,
        rule='or module:attribute naming a Task of your own (loaded on first use)')
    setting: str = param('easy', 'the setting of the challenge', choices=SETTINGS,
                         when=AT_RESET)
    chamber_width: float = param(0.84, 'chamber width; 1 cm per pixel of the 84 px image',
                                 unit='m', bounds=Bounds(0.01, 100.0), when=AT_RESET)
    chamber_height: float = param(0.84, 'chamber height', unit='m', bounds=Bounds(0.01, 100.0),
                                  rule=_STEM, when=AT_RESET)
    image_size: int = param(0, 'side of the square observation image', unit='px',
                            bounds=Bounds(8, 1024, integer=True, sentinel=0), when=AT_RESET,
                            rule="0 = the challenge's default (84, or 28 for shape)")
    episode_length: int = param(50, 'steps of an episode; truncated (not terminated) after it',
                                unit='steps', bounds=Bounds(1, 100_000, integer=True),
                                rule=_NODES, when=AT_RESET)
    light_density: int = param(200, 'photons scattered per episode',
                               bounds=Bounds(1, 100_000, integer=True), when=AT_RESET)
    photon_min_height: float = _fraction(0.25, 'photons lie above it', HEIGHT)
    first_branch_height: float = _fraction(0.2, 'length of the initial stem', rule=_STEM)
    branch_length: float = _fraction(0.1, 'length of every new segment')
    # The canopy has one column per branch thickness: a floor keeps it small.
    branch_thickness: float = param(0.015, 'thickness of a segment with no child', unit=WIDTH,
                                    bounds=Bounds(MIN_THICKNESS, 1.0), when=AT_RESET)
    max_branching: int = param(8, 'new segments per step at most, over all plants',
                               bounds=Bounds(1, 100, integer=True), rule=_NODES, when=AT_RESET)
    radius_of_influence: float = _fraction(0.15, 'photons farther from every node do not '
                                           'attract', rule=_KILL)
    kill_distance: float = _fraction(0.05, 'photons closer to the plant are used up', rule=_KILL)
    light_width: float = _fraction(0.25, 'initial beam width', rule=_WIDTH_ORDER)
    light_width_min: float = _fraction(0.1, 'narrowest beam', rule=_WIDTH_ORDER)
    light_width_max: float = _fraction(0.5, 'widest beam', rule=_WIDTH_ORDER)
    light_step_px: float = param(5.0, 'light move per action', unit='px of the 84 px image',
                                 bounds=Bounds(0.0, REFERENCE_IMAGE_SIZE, low_open=True),
                                 when=AT_RESET)
    spot_radius: float = _fraction(0.1, 'initial spotlight radius', rule=_SPOT_ORDER)
    spot_radius_min: float = _fraction(0.05, 'smallest spotlight radius', rule=_SPOT_ORDER)
    spot_radius_max: float = _fraction(0.3, 'largest spotlight radius', rule=_SPOT_ORDER)
    shading: bool = param(True, "photons under the plant's foliage are not lit", when=AT_RESET)
    target_radius: float = _fraction(0.03, "the reward's distance unit (see core.tasks)")
    n_plants: int = param(2, 'plants in a multi-plant challenge (fairness; at least 2); the '
                          'others grow one', bounds=Bounds(1, 16, integer=True), when=AT_RESET)
    digits: tuple[int, ...] = param(
        (), 'shape targets are drawn from these digits', bounds=Bounds(0, 9, integer=True),
        rule="empty = the setting's digit (easy 3, hard 0)", when=AT_RESET)
    shape_success: float = _fraction(0.5, 'Jaccard index at which the shape counts as reached',
                                     unit='1')

    def __post_init__(self) -> None:
        check(self)
        task = self.task
        if self.setting not in task.settings:
            raise ValueError(f'setting must be one of {task.settings} for {task.name}, '
                             f'got {echo(self.setting)}.')
        if self.max_branching * self.episode_length > MAX_NODES:
            raise ValueError(
                f'max_branching x episode_length ({self.max_branching} x {self.episode_length}'
                f' = {self.max_branching * self.episode_length}) must be in [1, {MAX_NODES}]: '
                f'the chamber keeps room for every node an episode can grow.')
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


def _check_order(low_name: str, low: float, mid_name: str, mid: float, high_name: str,
                 high: float) -> None:
    if not low <= mid <= high:
        raise ValueError(
            f'{low_name} ({low}) <= {mid_name} ({mid}) <= {high_name} ({high}) must hold.')
