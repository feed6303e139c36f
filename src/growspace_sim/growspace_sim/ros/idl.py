"""Cyclone DDS `IdlStruct` classes generated from the typestore, with ROS 2 DDS type names.

The classes name a DDS Topic's type (matching is by type name only, because rmw_cyclonedds
sends no XTypes type information) and serve as a second, independent CDR serialiser in tests.
The transport's hot path does not use them to encode: `sequence[uint8]` becomes a Python list of
ints there, 5-10x slower than rosbags on images.
"""

from __future__ import annotations

import dataclasses
import types
from typing import Any

import cyclonedds.idl.annotations as annotate
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as idl_types
from rosbags.typesys.base import Nodetype

from growspace_sim.ros import types as ros_types

# rosidl maps char to uint8 and byte to octet; both are one unsigned byte on the wire.
_PRIMITIVES = {
    'bool': bool, 'byte': idl_types.uint8, 'char': idl_types.uint8,
    'int8': idl_types.int8, 'uint8': idl_types.uint8, 'int16': idl_types.int16,
    'uint16': idl_types.uint16, 'int32': idl_types.int32, 'uint32': idl_types.uint32,
    'int64': idl_types.int64, 'uint64': idl_types.uint64,
    'float32': idl_types.float32, 'float64': idl_types.float64,
}
# rosidl's member name for messages without fields (one byte on the wire).
EMPTY_MEMBER = 'structure_needs_at_least_one_member'

_classes: dict[str, type[IdlStruct]] = {}


def _annotation(desc: tuple) -> Any:
    kind, arg = desc
    if kind == Nodetype.BASE:
        name, bound = arg
        if name == 'string':
            return idl_types.bounded_str[bound] if bound else str
        return _PRIMITIVES[name]
    if kind == Nodetype.NAME:
        return idl_class(arg)
    sub, length = arg
    if kind == Nodetype.ARRAY:
        return idl_types.array[_annotation(sub), length]
    return idl_types.sequence[_annotation(sub), length] if length else idl_types.sequence[
        _annotation(sub)]


def _default_value(desc: tuple) -> Any:
    kind, arg = desc
    if kind == Nodetype.BASE:
        name = arg[0]
        if name == 'string':
            return ''
        return False if name == 'bool' else 0.0 if name.startswith('float') else 0
    if kind == Nodetype.NAME:
        return idl_class(arg)()
    sub, length = arg
    return [_default_value(sub) for _ in range(length if kind == Nodetype.ARRAY else 0)]


def _default_field(desc: tuple) -> dataclasses.Field:
    if desc[0] == Nodetype.BASE:
        return dataclasses.field(default=_default_value(desc))
    return dataclasses.field(default_factory=lambda: _default_value(desc))


def idl_class(typename: str) -> type[IdlStruct]:
    """Return (and cache) the final, keyless `IdlStruct` class of a ROS message type.

    Args:
        typename: e.g. `sensor_msgs/msg/Image`; its class is named
            `sensor_msgs::msg::dds_::Image_` on the wire.

    Returns:
        A dataclass whose fields default to zeros, empty strings and empty sequences.

    Raises:
        KeyError: The type is unknown to the typestore.
    """
    if typename in _classes:
        return _classes[typename]
    fielddefs = ros_types.typestore().fielddefs
    if typename not in fielddefs:
        raise KeyError(f'Unknown message type {typename!r}')
    fields = fielddefs[typename][1] or [(EMPTY_MEMBER, (Nodetype.BASE, ('uint8', 0)))]
    namespace: dict[str, Any] = {
        '__annotations__': {name: _annotation(desc) for name, desc in fields},
        **{name: _default_field(desc) for name, desc in fields},
    }
    short = typename.rsplit('/', 1)[1]
    cls = types.new_class(short, (IdlStruct,), {'typename': ros_types.dds_type_name(typename)},
                          lambda ns: ns.update(namespace))
    cls = annotate.final(dataclasses.dataclass(cls))
    _classes[typename] = cls
    return cls


def from_msg(msg: Any, typename: str) -> IdlStruct:
    """Convert a rosbags message into an instance of the type's `IdlStruct` class.

    Args:
        msg: A rosbags message (e.g. from `types.new()`).
        typename: Its type name.

    Returns:
        The equivalent `IdlStruct` value.
    """
    return _convert(ros_types.to_plain(msg), (Nodetype.NAME, typename))


def _convert(value: Any, desc: tuple) -> Any:
    kind, arg = desc
    if kind == Nodetype.NAME:
        fields = ros_types.typestore().fielddefs[arg][1]
        if not fields:
            return idl_class(arg)()
        return idl_class(arg)(**{name: _convert(value[name], sub) for name, sub in fields})
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return [_convert(item, arg[0]) for item in value]
    return value
