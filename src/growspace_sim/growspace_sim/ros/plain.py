"""Plain values (from YAML, JSON, a command line) checked against a message type's fields.

The CDR writer packs each field with ``struct``: a value out of its field's range or of the
wrong kind would fail there with an error that names neither. ``check`` says which field, which
value and what is allowed first, as the generated rclpy classes would.
"""

from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any

from rosbags.typesys.base import Nodetype
from rosbags.typesys.store import Typestore

from growspace_sim.core.errors import echo

FLOAT32_MAX = 3.4028234663852886e38  # largest finite float32


def _int_range(name: str) -> tuple[int, int] | None:
    """(low, high) of an integer ROS type (``byte`` and ``char`` are octets), else None."""
    if name in ('byte', 'char'):
        return 0, 255
    if not name.startswith(('int', 'uint')):
        return None
    bits = int(name.removeprefix('u').removeprefix('int'))
    return (0, 2 ** bits - 1) if name.startswith('u') else (-2 ** (bits - 1), 2 ** (bits - 1) - 1)


def _base_problem(base: str, value: Any) -> str | None:
    """What is allowed in a field of ROS base type ``base``, if ``value`` is not; else None."""
    if base == 'bool':
        return None if isinstance(value, bool) else 'true or false'
    if base in ('string', 'wstring'):
        return None if isinstance(value, str) else 'a string'
    bounds = _int_range(base)
    if bounds is not None:
        low, high = bounds
        ok = isinstance(value, Integral) and not isinstance(value, bool) and \
            low <= value <= high
        return None if ok else f'an integer in [{low}, {high}] ({base})'
    ok = isinstance(value, Real) and not isinstance(value, bool)
    if ok and base == 'float32' and math.isfinite(value):
        ok = abs(value) <= FLOAT32_MAX
    return None if ok else f'a number ({base}{", |x| <= 3.4e38" if base == "float32" else ""})'


def check(typestore: Typestore, typename: str, value: Any, path: str = '') -> None:
    """Check plain values (nested dicts and lists) against the fields of ``typename``.

    Fields left out are fine (they get defaults); unknown field names are left to the message
    builder, which lists the type's fields.

    Args:
        typestore: the types (``types.typestore()``); passed in, so this module needs none of
            ``types``, which builds messages with it.
        typename: e.g. ``growspace_msgs/msg/LightCommand``.
        value: the field values, nested messages as dicts.
        path: the dotted name of this message in an outer one ('' at the top).

    Raises:
        ValueError: naming the first field whose value does not fit, the value and what is
            allowed, e.g. ``step_id = -1 is not allowed; expected an integer in
            [0, 18446744073709551615] (uint64).``
    """
    if not isinstance(value, dict):
        raise ValueError(f'{path or typename} = {echo(value)} is not allowed; expected a '
                         f'mapping of the fields of {typename}.')
    fields = dict(typestore.fielddefs[typename][1])
    for name, item in value.items():
        if name in fields:
            _check_field(typestore, f'{path}.{name}' if path else name, fields[name], item)


def _check_field(typestore: Typestore, path: str, desc: tuple, item: Any) -> None:
    kind, arg = desc
    if kind == Nodetype.NAME:
        check(typestore, arg, item, path)
    elif kind == Nodetype.BASE:
        allowed = _base_problem(arg[0], item)
        if allowed is not None:
            raise ValueError(f'{path} = {echo(item)} is not allowed; expected {allowed}.')
    elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        if isinstance(item, (str, bytes, dict)) or not hasattr(item, '__len__'):
            raise ValueError(f'{path} = {echo(item)} is not allowed; expected a list.')
        for i, sub in enumerate(item):
            _check_field(typestore, f'{path}[{i}]', arg[0], sub)
