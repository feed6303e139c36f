"""The node's parameters: every ``SimConfig`` field plus a few node settings, and their parsing.

The names, defaults and types come from ``SimConfig`` and ``NodeParams`` alone; the descriptions
(with units) are the trailing comments of their fields, read from the source, so the ROS
parameter descriptors and ``config/growspace.yaml`` cannot drift from the dataclasses. rcl parses
the command line and params files; ``check_type`` and ``build`` validate what it found.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import functools
import inspect
import re
from typing import Any

import yaml

from growspace_sim.ros.convert import MAX_SEED
from growspace_sim.core import config as sim_config
from growspace_sim.core.config import Bounds, SimConfig

MODES = ('lockstep', 'realtime')
DEFAULT_NODE_NAME = 'growspace_sim'
MAX_RATE_HZ = 10_000.0
FRAME_RULE = 'a frame name of letters, digits, _ and /'
NODE_BOUNDS = {'rate_hz': Bounds(0.0, MAX_RATE_HZ, low_open=True),
               'seed': Bounds(0, MAX_SEED, integer=True, sentinel=-1)}
NODE_RULES = {'seed': '-1 = draw a seed at random (it is published)',
              'frame_id': FRAME_RULE, 'image_frame_id': FRAME_RULE}
# When a change takes effect; the node's parameter descriptors say it. SimConfig fields apply
# at the next reset (the episode under way keeps its chamber), these at once, the rest
# (read-only) at start-up.
LIVE = frozenset({'rate_hz', 'auto_reset'})
REALTIME_ONLY = frozenset({'rate_hz'})  # in lockstep, sim time per step stays as recorded


class ParamError(ValueError):
    """An invalid parameter; the message names it, its value and what is allowed."""


def check_bounds(settings: Any, bounds: dict[str, Bounds]) -> None:
    """Check a settings object's number fields against their bounds.

    Raises:
        ParamError: naming the first field out of bounds, its value and what is allowed.
    """
    for name, field_bounds in bounds.items():
        try:
            field_bounds.check(name, getattr(settings, name))
        except ValueError as e:
            raise ParamError(str(e)) from None


@dataclass(frozen=True)
class NodeParams:
    """Settings of the node itself (not of the simulated chamber), validated on construction."""

    mode: str = 'lockstep'  # lockstep: one step per LightCommand; realtime: step on a timer
    rate_hz: float = 10.0  # Hz; timer rate in realtime mode; sim time advances 1/rate_hz a step
    seed: int = -1  # seed of the first episode; -1 = draw one at random (it is published)
    auto_reset: bool = True  # realtime mode: start a new episode when one ends
    frame_id: str = 'chamber'  # frame of plant state, light state and step results
    image_frame_id: str = 'chamber_camera'  # frame of the camera images
    record_path: str = ''  # MCAP file to record every message to; empty = no recording

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ParamError(f'mode must be one of {MODES}, got {self.mode!r}.')
        check_bounds(self, NODE_BOUNDS)
        if not isinstance(self.auto_reset, bool):
            raise ParamError(f'auto_reset must be a bool, got {self.auto_reset!r}.')
        for name in ('frame_id', 'image_frame_id'):
            value = getattr(self, name)
            if not isinstance(value, str) or not re.fullmatch(r'[A-Za-z0-9_/]+', value):
                raise ParamError(f'{name} must be a non-empty frame name of letters, digits, '
                                 f'_ and /, got {value!r}.')
        if not isinstance(self.record_path, str):
            raise ParamError(f'record_path must be a string, got {self.record_path!r}.')

    @property
    def period_ns(self) -> int:
        """Sim time of one step [ns]."""
        return max(1, round(1e9 / self.rate_hz))


@dataclass(frozen=True)
class ParamSpec:
    """One ROS parameter: its name, default, description (with unit) and constraints."""

    name: str
    default: Any
    description: str
    owner: type  # SimConfig or NodeParams
    bounds: Bounds | None = None  # numbers: the range (a ROS integer or floating-point range)
    rules: str = ''  # what else is allowed, in words (ROS additional_constraints)
    runtime: bool = True  # the node takes changes while it runs (sim_node; not gantry_node)

    @property
    def when(self) -> str:
        """When a new value takes effect."""
        if not self.runtime:
            return 'at start-up (read-only)'
        if self.owner is SimConfig:
            return 'at the next reset'
        if self.name in REALTIME_ONLY:
            return 'at once, in realtime mode (read-only in lockstep)'
        return 'at once' if self.name in LIVE else 'at start-up (read-only)'

    def read_only(self, mode: str) -> bool:
        """Whether the running node refuses changes (in ``mode``)."""
        if not self.runtime:
            return True
        if self.owner is SimConfig:
            return False
        return self.name not in LIVE or (self.name in REALTIME_ONLY and mode != 'realtime')


@functools.cache
def _field_comments(cls: type) -> dict[str, str]:
    # 'name: type = default  # comment' lines of the dataclass body.
    pattern = re.compile(r'^\s+(\w+):[^=]+=[^#]*#\s*(.+)$')
    found: dict[str, str] = {}
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):  # no source installed: descriptions stay empty
        return found
    for line in source.splitlines():
        match = pattern.match(line)
        if match:
            found[match.group(1)] = match.group(2).strip()
    return found


def specs_of(*classes: type, bounds: dict[str, Bounds] | None = None,
             rules: dict[str, str] | None = None,
             runtime: bool = True) -> tuple[ParamSpec, ...]:
    """The parameters of some dataclasses, in class and field order (the gantry node adds its
    own settings class to SimConfig this way).

    Args:
        classes: The dataclasses; SimConfig's bounds and rules are known here.
        bounds: The number ranges of the other classes' fields, by name.
        rules: Other constraints of their fields, in words, by name.
        runtime: False for a node that reads its parameters at start-up only: every one is
            read-only then.
    """
    all_bounds = {**sim_config.BOUNDS, **(bounds or {})}
    all_rules = {**sim_config.RULES, **(rules or {})}
    out = []
    for cls in classes:
        comments = _field_comments(cls)
        for field in dataclasses.fields(cls):
            name = field.name
            allowed = sim_config.choices(name) if cls is SimConfig else \
                (MODES if name == 'mode' else ())
            text = '; '.join(filter(None, (
                f'one of {", ".join(allowed)}' if allowed else '',
                'greater than 0' if name in all_bounds and all_bounds[name].low_open else '',
                all_rules.get(name, ''))))
            out.append(ParamSpec(name, field.default, comments.get(name, ''), cls,
                                 all_bounds.get(name), text, runtime))
    return tuple(out)


@functools.cache
def specs() -> tuple[ParamSpec, ...]:
    """Every parameter of the node: SimConfig fields first, then NodeParams, in field order."""
    return specs_of(SimConfig, NodeParams, bounds=NODE_BOUNDS, rules=NODE_RULES)


def defaults() -> dict[str, Any]:
    """Default value of every parameter, tuples as lists (their ROS form)."""
    return {s.name: list(s.default) if isinstance(s.default, tuple) else s.default
            for s in specs()}


def check_type(spec: ParamSpec, value: Any) -> Any:
    """Coerce a YAML value to the parameter's type as ROS would, or raise ParamError (also for
    a number outside the parameter's range)."""
    default = spec.default
    if isinstance(default, bool):
        ok = isinstance(value, bool)
        expected = 'a bool (true or false)'
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
        expected = 'an integer'
    elif isinstance(default, float):
        # rclpy would refuse `-p rate_hz:=20` for a double; an integer is a number too.
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
        expected = 'a number'
    elif isinstance(default, str):
        ok = isinstance(value, str)
        expected = 'a string'
    else:  # the digits tuple
        ok = isinstance(value, (list, tuple)) and all(
            isinstance(v, int) and not isinstance(v, bool) for v in value)
        value = tuple(value) if ok else value
        expected = 'a list of integers'
    if not ok:
        raise ParamError(f'{spec.name} must be {expected}, got {value!r}.')
    if spec.bounds is not None:  # ROS would refuse to declare it out of its range
        try:
            spec.bounds.check(spec.name, value)
        except ValueError as e:
            raise ParamError(str(e)) from None
    return value


def build(values: dict[str, Any], settings: type = NodeParams) -> tuple[SimConfig, Any]:
    """Validate parameter values (missing ones get their defaults).

    Args:
        values: parameter name -> value as parsed from YAML or declared in rclpy.
        settings: the node's own settings dataclass (``NodeParams`` for sim_node).

    Returns:
        The chamber configuration and the node settings.

    Raises:
        ParamError: one line naming the parameter, its value and what is allowed.
    """
    by_name = {s.name: s for s in (specs() if settings is NodeParams else
                                   specs_of(SimConfig, settings, runtime=False))}
    unknown = sorted(set(values) - set(by_name))
    if unknown:
        raise ParamError(f'unknown parameter(s) {unknown}; allowed: {sorted(by_name)}.')
    sim_values: dict[str, Any] = {}
    node_values: dict[str, Any] = {}
    for name, value in values.items():
        spec = by_name[name]
        target = sim_values if spec.owner is SimConfig else node_values
        target[name] = check_type(spec, value)
    try:
        cfg = SimConfig.from_dict(sim_values)
        node = settings(**node_values)
    except ValueError as e:
        raise ParamError(str(e)) from None
    return cfg, node


def as_values(cfg: SimConfig, node: NodeParams) -> dict[str, Any]:
    """The parameter values of a configuration (the inverse of ``build``), tuples as lists."""
    out = {}
    for obj in (cfg, node):
        for field in dataclasses.fields(obj):
            value = getattr(obj, field.name)
            out[field.name] = list(value) if isinstance(value, tuple) else value
    return out


def to_yaml(values: dict[str, Any] | None = None, node_name: str = '/**') -> str:
    """A ROS params file of every parameter, with each description as a comment."""
    values = defaults() if values is None else values
    lines = [f'{node_name}:', '  ros__parameters:']
    for spec in specs():
        value = values[spec.name]
        text = yaml.safe_dump(value, default_flow_style=True).strip()
        if text.endswith('\n...') or text.endswith('...'):
            text = text.rsplit('\n', 1)[0]
        if isinstance(value, float):
            text = repr(value)  # 0.0-style, so ROS types it as a double
        comment = f'  # {spec.description}' if spec.description else ''
        # ROS 2's params-file parser cannot type an empty list, so an empty default is left as
        # a comment (unset means the same); give a non-empty list to use it.
        unset = '# ' if isinstance(value, (list, tuple)) and not value else ''
        lines.append(f'    {unset}{spec.name}: {text}{comment}')
    return '\n'.join(lines) + '\n'
