"""The node's parameters: every ``SimConfig`` field plus a few node settings, and their parsing.

Each parameter is declared once, on its dataclass field (``core.schema.param``: meaning, unit,
range, choices, rules, when a change applies). The ROS parameter descriptors, the params file
``config/growspace.yaml`` (``to_yaml``), the README's table (``python -m growspace_sim.node.params
--markdown``) and the validation all come from those declarations. rcl parses the command line
and params files; ``check_type`` and ``build`` validate what it found.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import dataclasses
import functools
import sys
from typing import Any

import yaml

from growspace_sim.core import schema
from growspace_sim.core.config import SimConfig
from growspace_sim.core.schema import AT_ONCE, AT_ONCE_REALTIME, AT_START, Bounds, Param, param
from growspace_sim.ros.convert import MAX_SEED

MODES = ('lockstep', 'realtime')
DEFAULT_NODE_NAME = 'growspace_sim'
MAX_RATE_HZ = 10_000.0
FRAME = r'[A-Za-z0-9_/]+'
FRAME_DOC = 'a frame name of letters, digits, _ and /'


class ParamError(ValueError):
    """An invalid parameter; the message names it, its value and what is allowed."""


def seed_param(doc: str) -> Any:
    """The ``seed`` field of a node's settings (-1 draws one)."""
    return param(-1, doc, bounds=Bounds(0, MAX_SEED, integer=True, sentinel=-1),
                 rule='-1 = draw a seed at random (it is published)')


def frame_param(default: str, doc: str) -> Any:
    """A ``frame_id`` field of a node's settings."""
    return param(default, doc, pattern=FRAME, pattern_doc=FRAME_DOC)


def mode_param(doc: str) -> Any:
    """The ``mode`` field of a node's settings."""
    return param('lockstep', doc, choices=MODES)


def check(settings: Any) -> None:
    """``schema.check`` for node settings: the same one-line message, as a ``ParamError``."""
    try:
        schema.check(settings)
    except ValueError as e:
        raise ParamError(str(e)) from None


@dataclass(frozen=True)
class NodeParams:
    """Settings of the node itself (not of the simulated chamber), validated on construction."""

    mode: str = mode_param('lockstep: one step per LightCommand; realtime: step on a timer')
    rate_hz: float = param(10.0, 'timer rate in realtime mode; sim time advances 1/rate_hz a '
                           'step', unit='Hz', bounds=Bounds(0.0, MAX_RATE_HZ, low_open=True),
                           when=AT_ONCE_REALTIME)
    seed: int = seed_param('seed of the first episode')
    auto_reset: bool = param(True, 'realtime mode: start a new episode when one ends',
                             when=AT_ONCE)
    frame_id: str = frame_param('chamber', 'frame of plant state, light state and step results')
    image_frame_id: str = frame_param('chamber_camera', 'frame of the camera images')
    record_path: str = param('', 'MCAP file to record every message to; empty = no recording')
    record_max_bytes: int = param(0, 'split the recording into files of about this many message '
                                  'bytes: record_path is then a directory of NAME_0.mcap, '
                                  'NAME_1.mcap, ... (rosbag2 --max-bag-size); 0 = one file',
                                  unit='B', bounds=Bounds(0, 10**15, integer=True))
    record_max_duration_s: float = param(0.0, 'split the recording into files of at most this '
                                         'much sim time each (rosbag2 --max-bag-duration); '
                                         '0 = no duration limit', unit='s', bounds=Bounds(0.0))
    resume_path: str = param('', 'go on where this recording (a file or a split directory) '
                             'ends: its last episode re-simulated bit for bit to its last step, '
                             'the next command steps the one after; the same split directory '
                             'as record_path continues it with a new file; empty = a new episode')

    def __post_init__(self) -> None:
        check(self)

    @property
    def period_ns(self) -> int:
        """Sim time of one step [ns]."""
        return max(1, round(1e9 / self.rate_hz))


@dataclass(frozen=True)
class ParamSpec:
    """One ROS parameter of a node: its name, default and declaration.

    Attributes:
        name: The field (and parameter) name.
        default: Its default value.
        param: Its declaration (meaning, unit, range, choices, rules, when it applies).
        owner: The settings dataclass it belongs to.
        runtime: The node takes changes while it runs (sim_node; not gantry_node).
    """

    name: str
    default: Any
    param: Param
    owner: type
    runtime: bool = True

    @property
    def description(self) -> str:
        """Unit and meaning."""
        return self.param.description

    @property
    def bounds(self) -> Bounds | None:
        return self.param.bounds

    @property
    def rules(self) -> str:
        """What is allowed beyond the type and range, in words."""
        return self.param.constraints

    @property
    def when(self) -> str:
        """When a new value takes effect."""
        return self.param.when if self.runtime else AT_START

    def read_only(self, mode: str) -> bool:
        """Whether the running node refuses changes (in ``mode``)."""
        return self.when == AT_START or (self.when == AT_ONCE_REALTIME and mode != 'realtime')


def specs_of(*classes: type, runtime: bool = True) -> tuple[ParamSpec, ...]:
    """The parameters of some settings dataclasses, in class and field order (the gantry node
    adds its own settings class to SimConfig this way).

    Args:
        classes: The dataclasses, their fields declared with ``core.schema.param``.
        runtime: False for a node that reads its parameters at start-up only: every one is
            read-only then.
    """
    return tuple(ParamSpec(field.name, field.default, declaration, cls, runtime)
                 for cls in classes for field, declaration in schema.declared(cls))


@functools.cache
def specs() -> tuple[ParamSpec, ...]:
    """Every parameter of the node: SimConfig fields first, then NodeParams, in field order."""
    return specs_of(SimConfig, NodeParams)


def defaults() -> dict[str, Any]:
    """Default value of every parameter, tuples as lists (their ROS form)."""
    return {s.name: list(s.default) if isinstance(s.default, tuple) else s.default
            for s in specs()}


def check_type(spec: ParamSpec, value: Any) -> Any:
    """Coerce a YAML or command-line value to the parameter's type as ROS would, or raise
    ParamError (also for a value that its declaration does not allow)."""
    try:
        value = schema.coerce(spec.default, spec.name, value)
        spec.param.check(spec.name, value)
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
        comment = '; '.join(filter(None, (spec.description,
                                          spec.param.allowed_text(spec.default))))
        # ROS 2's params-file parser cannot type an empty list, so an empty default is left as
        # a comment (unset means the same); give a non-empty list to use it.
        unset = '# ' if isinstance(value, (list, tuple)) and not value else ''
        lines.append(f'    {unset}{spec.name}: {text}  # {comment}')
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    """Print sim_node's parameters as a params file (the default) or as the README's table."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument('--markdown', action='store_true', help="the README's table")
    args = parser.parse_args(argv)
    print(schema.markdown_table(SimConfig, NodeParams) if args.markdown else to_yaml(), end='')
    return 0


if __name__ == '__main__':
    sys.exit(main())
