"""ROS 2 message types without ROS: a rosbags typestore built from the growspace_msgs files.

The `.msg`/`.srv` files of `growspace_msgs` are the single source of truth. This module parses
them (plus the standard Jazzy definitions shipped with rosbags) and offers CDR (de)serialisation,
the MCAP schema text and the REP-2011 type hash of every type. It is the codec of the whole
project: the rclpy transport publishes and takes these CDR bytes as serialized messages, and
recording and replay work with them on machines without a ROS build.

Type names are the ROS 2 long form, e.g. `growspace_msgs/msg/LightCommand`,
`sensor_msgs/msg/Image`, `growspace_msgs/srv/Reset_Request`.
"""

from __future__ import annotations

import dataclasses
import functools
import os
from pathlib import Path
import re
from typing import Any

import numpy as np
from rosbags.typesys import get_typestore, get_types_from_msg, Stores
from rosbags.typesys.base import Nodetype
from rosbags.typesys.store import Typestore

from growspace_sim.ros import plain

PACKAGE = 'growspace_msgs'
MSGS_DIR_ENV = 'GROWSPACE_MSGS_DIR'

# Types defined by growspace_msgs, in the order of the files.
LIGHT_COMMAND = 'growspace_msgs/msg/LightCommand'
PLANT_STATE = 'growspace_msgs/msg/PlantState'
RESET_REQUEST = 'growspace_msgs/msg/ResetRequest'
STEP_RESULT = 'growspace_msgs/msg/StepResult'
RESET = 'growspace_msgs/srv/Reset'
RESET_SRV_REQUEST = f'{RESET}_Request'
RESET_SRV_RESPONSE = f'{RESET}_Response'
CAMERA_MEASUREMENT = 'growspace_msgs/msg/CameraMeasurement'
CAPTURE = 'growspace_msgs/srv/Capture'
# The standard types a chamber speaks besides its own (every type name is spelled here once).
IMAGE = 'sensor_msgs/msg/Image'
CLOCK = 'rosgraph_msgs/msg/Clock'
STRING = 'std_msgs/msg/String'
COMPRESSED_IMAGE = 'sensor_msgs/msg/CompressedImage'
DIAGNOSTICS = 'diagnostic_msgs/msg/DiagnosticArray'

# Standard services our nodes offer that rosbags' Jazzy store lacks (std_srvs/srv/Trigger.srv;
# an empty request is the one-byte placeholder struct rosidl generates).
STANDARD_SERVICES = {
    'std_srvs/srv/Trigger_Request': 'uint8 structure_needs_at_least_one_member',
    'std_srvs/srv/Trigger_Response': 'bool success\nstring message',
}

# CDR encapsulation header of XCDR1 little endian, the only form ROS 2 rmw layers write.
CDR_LE_HEADER = b'\x00\x01\x00\x00'

_NUMPY_DTYPES = {
    'bool': np.bool_, 'byte': np.uint8, 'char': np.uint8, 'int8': np.int8, 'uint8': np.uint8,
    'int16': np.int16, 'uint16': np.uint16, 'int32': np.int32, 'uint32': np.uint32,
    'int64': np.int64, 'uint64': np.uint64, 'float32': np.float32, 'float64': np.float64,
}
_SRV_SEPARATOR = re.compile(r'^---[ \t]*$', re.MULTILINE)


class CdrError(ValueError):
    """Raised when bytes are not a valid XCDR1 encoding of the expected type."""


def msgs_dir() -> Path:
    """Find the growspace_msgs package directory holding `msg/` and `srv/`.

    Looked up in order: the directory named by $GROWSPACE_MSGS_DIR, the source tree next to this
    package (`src/growspace_msgs`), the installed ament share directory.

    Returns:
        The package directory.

    Raises:
        FileNotFoundError: No directory with `msg/LightCommand.msg` was found.
    """
    tried = []
    env = os.environ.get(MSGS_DIR_ENV)
    if env:
        candidates = [Path(env)]
    else:
        # ros/ -> growspace_sim/ (module) -> growspace_sim/ (package) -> src/
        candidates = [Path(__file__).resolve().parents[3] / PACKAGE]
        try:
            from ament_index_python.packages import get_package_share_directory
            candidates.append(Path(get_package_share_directory(PACKAGE)))
        except Exception:  # noqa: BLE001 - not installed or not found: try the next place
            pass
    for path in candidates:
        if (path / 'msg' / 'LightCommand.msg').is_file():
            return path
        tried.append(str(path))
    where = f'${MSGS_DIR_ENV}={env!r}' if env else ', '.join(tried)
    raise FileNotFoundError(f'No {PACKAGE} message files (msg/LightCommand.msg) found in {where}')


def split_srv(text: str) -> tuple[str, str]:
    """Split `.srv` text into its request and response `.msg` texts.

    Args:
        text: Content of a `.srv` file.

    Returns:
        The request and the response definitions.

    Raises:
        ValueError: The text does not contain exactly one `---` separator line.
    """
    parts = _SRV_SEPARATOR.split(text)
    if len(parts) != 2:
        raise ValueError(f'A .srv needs exactly one "---" line, found {len(parts) - 1}')
    return parts[0], parts[1]


def interface_texts(root: Path | None = None) -> dict[str, str]:
    """Read the message definitions of growspace_msgs, services split into two messages.

    Args:
        root: Package directory; found with `msgs_dir()` when None.

    Returns:
        Map of type name to `.msg` text, e.g. `growspace_msgs/srv/Reset_Request`.
    """
    root = msgs_dir() if root is None else root
    texts = {}
    for path in sorted((root / 'msg').glob('*.msg')):
        texts[f'{PACKAGE}/msg/{path.stem}'] = path.read_text(encoding='utf-8')
    for path in sorted((root / 'srv').glob('*.srv')):
        request, response = split_srv(path.read_text(encoding='utf-8'))
        texts[f'{PACKAGE}/srv/{path.stem}_Request'] = request
        texts[f'{PACKAGE}/srv/{path.stem}_Response'] = response
    return texts


def parse_definitions(texts: dict[str, str]) -> dict[str, Any]:
    """Parse `.msg` texts into a rosbags types dictionary.

    Args:
        texts: Map of type name to `.msg` text.

    Returns:
        The rosbags types dictionary (type name -> (constants, fields)).
    """
    typs = {}
    for name, text in texts.items():
        pkg, kind, short = name.split('/')
        # rosbags forces '/msg/' into a type name, so parse under that name and rename.
        parsed = get_types_from_msg(text, f'{pkg}/msg/{short}')
        typs[name] = parsed[f'{pkg}/msg/{short}']
    return typs


@functools.cache
def typestore() -> Typestore:
    """Return the process-wide typestore: ROS 2 Jazzy standard types plus growspace_msgs.

    Returns:
        The typestore, built on first use.
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(parse_definitions({**interface_texts(), **STANDARD_SERVICES}))
    return store


def growspace_types() -> list[str]:
    """List the type names defined by growspace_msgs, services as request and response.

    Returns:
        The type names.
    """
    return sorted(name for name in typestore().fielddefs if name.startswith(f'{PACKAGE}/'))


def msg_class(typename: str) -> type:
    """Return the rosbags dataclass of a message type.

    Args:
        typename: e.g. `growspace_msgs/msg/StepResult`.

    Returns:
        The message class.

    Raises:
        KeyError: The type is unknown.
    """
    try:
        return typestore().types[typename]
    except KeyError:
        raise KeyError(f'Unknown message type {typename!r}') from None


def _default(desc: tuple) -> Any:
    kind, arg = desc
    if kind == Nodetype.BASE:
        name = arg[0]
        if name == 'string':
            return ''
        return _NUMPY_DTYPES[name](0).item()
    if kind == Nodetype.NAME:
        return new(arg)
    (sub_kind, sub_arg), length = arg
    count = length if kind == Nodetype.ARRAY else 0
    if sub_kind == Nodetype.BASE and sub_arg[0] != 'string':
        return np.zeros(count, dtype=_NUMPY_DTYPES[sub_arg[0]])
    return [_default((sub_kind, sub_arg)) for _ in range(count)]


def _coerce(name: str, desc: tuple, value: Any) -> Any:
    # rosbags serialises numeric arrays from numpy only; accept any sequence from callers.
    kind, arg = desc
    if kind not in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return value
    (sub_kind, sub_arg), length = arg
    if sub_kind == Nodetype.BASE and sub_arg[0] != 'string':
        value = np.asarray(value, dtype=_NUMPY_DTYPES[sub_arg[0]]).reshape(-1)
    if kind == Nodetype.ARRAY and len(value) != length:
        raise ValueError(f'Field {name!r} needs exactly {length} elements, got {len(value)}')
    return value


def new(typename: str, **fields: Any) -> Any:
    """Build a message, filling unnamed fields with zeros, empty strings and empty arrays.

    Numeric arrays may be given as lists or numpy arrays; they are converted to the field's dtype.

    Args:
        typename: e.g. `growspace_msgs/msg/LightCommand`.
        **fields: Field values.

    Returns:
        The message.

    Raises:
        KeyError: The type is unknown.
        TypeError: A field name does not exist in the type.
        ValueError: A fixed-size array has the wrong length.
    """
    cls = msg_class(typename)
    defs = dict(typestore().fielddefs[typename][1])
    unknown = set(fields) - set(defs)
    if unknown:
        raise TypeError(f'{typename} has no field(s) {sorted(unknown)}; fields: {list(defs)}')
    values = {
        name: _coerce(name, desc, fields[name]) if name in fields else _default(desc)
        for name, desc in defs.items()
    }
    return cls(**values)


def from_plain(typename: str, value: dict[str, Any]) -> Any:
    """Build a message from nested dicts and lists (the inverse of `to_plain`).

    Args:
        typename: The message type name.
        value: Field values; nested messages as dicts; missing fields get defaults.

    Returns:
        The message.

    Raises:
        KeyError: The type is unknown.
        TypeError: A field name does not exist in the type.
        ValueError: A value does not fit its field (``plain.check``: names the field, the
            value and what is allowed) or a fixed-size array has the wrong length.
    """
    if typename in typestore().fielddefs:
        plain.check(typestore(), typename, value)

    def build(desc: tuple, item: Any) -> Any:
        kind, arg = desc
        if kind == Nodetype.NAME and isinstance(item, dict):
            return from_plain(arg, item)
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and arg[0][0] == Nodetype.NAME:
            return [build(arg[0], sub) for sub in item]
        return item

    defs = dict(typestore().fielddefs[typename][1]) if typename in typestore().fielddefs else {}
    return new(typename, **{name: build(defs[name], item) if name in defs else item
                            for name, item in value.items()})


def serialize(msg: Any, typename: str) -> bytes:
    """Serialise a message to CDR (XCDR1, little endian) with its 4-byte encapsulation header.

    The result is what rmw writes to DDS and what rosbag2 stores in MCAP.

    Args:
        msg: A message of type `typename`, e.g. from `new()`.
        typename: The message type name.

    Returns:
        The serialised bytes, not padded.
    """
    store = typestore()
    getsize, write = _cdr_functions(typename)
    data = bytearray(4 + getsize(0, msg, store))
    data[1] = 1  # encapsulation header 00 01 00 00: CDR, little endian
    write(memoryview(data)[4:], 0, msg, store)
    return bytes(data)


@functools.cache
def _cdr_functions(typename: str) -> tuple[Any, Any]:
    """rosbags' generated size and little-endian writer of a type, looked up once.

    ``Typestore.serialize_cdr`` does exactly this per call; keeping the two functions saves
    the lookup on the node's hot path (the bytes are the same, tests/node/test_msgs_wire.py).
    """
    msgdef = typestore().get_msgdef(typename)
    return msgdef.getsize_cdr, msgdef.serialize_cdr_le


@functools.cache
def _cdr_readers(typename: str) -> tuple[Any, Any, type]:
    msgdef = typestore().get_msgdef(typename)
    return msgdef.deserialize_cdr_le, msgdef.deserialize_cdr_be, msgdef.cls


def deserialize(data: bytes | memoryview, typename: str, any_tail: bool = False) -> Any:
    """Decode CDR bytes (encapsulation header included) into a message.

    Data from the network is untrusted, so every failure comes out as one exception type.

    Args:
        data: The CDR payload, possibly followed by up to 7 pad bytes: rmw_fastrtps (Fast CDR)
            pads some messages to 8 bytes, beyond the 3 that ``Typestore.deserialize_cdr``
            accepts (tests/node/test_msgs_wire.py).
        typename: The expected message type name.
        any_tail: Accept any number of bytes after the message: only for bytes from
            ``rclpy.serialization.serialize_message`` in this process, whose length is Fast
            CDR's size estimate, 8 or 16 bytes beyond the data for some nested messages
            (measured on ``Capture_Response``; ``rclpy_transport.from_rclpy``).

    Returns:
        The message.

    Raises:
        CdrError: The bytes are not a valid XCDR1 encoding of `typename`.
    """
    if len(data) < 4 or bytes(data[:2]) not in (b'\x00\x00', b'\x00\x01'):
        raise CdrError(f'Not an XCDR1 payload for {typename}: header {bytes(data[:4]).hex()!r}')
    try:
        read_le, read_be, cls = _cdr_readers(typename)
        msg, end = (read_le if data[1] else read_be)(memoryview(data)[4:], 0, cls, typestore())
    except Exception as exc:  # noqa: BLE001 - any decoder failure means malformed input
        raise CdrError(f'Malformed CDR for {typename} ({len(data)} B): {exc}') from exc
    if not 0 <= len(data) - 4 - end <= (len(data) if any_tail else 7):
        raise CdrError(f'Malformed CDR for {typename} ({len(data)} B): {len(data) - 4 - end} '
                       f'bytes after the message; at most 7 pad bytes are allowed.')
    return msg


def to_plain(msg: Any) -> Any:
    """Convert a message into nested dicts and lists of Python scalars (for comparison, JSON).

    Args:
        msg: A message, or any value inside one.

    Returns:
        The plain value.
    """
    typename = getattr(msg, '__msgtype__', None)
    if typename in typestore().fielddefs:
        # rosbags classes also list the type name and the constants as dataclass fields.
        fields = typestore().fielddefs[typename][1]
        return {name: to_plain(getattr(msg, name)) for name, _ in fields}
    if dataclasses.is_dataclass(msg):
        return {f.name: to_plain(getattr(msg, f.name)) for f in dataclasses.fields(msg)}
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, (list, tuple)):
        return [to_plain(item) for item in msg]
    if isinstance(msg, np.generic):
        return msg.item()
    return msg


def msgdef(typename: str) -> str:
    """Return the concatenated `ros2msg` definition of a type, as rosbag2 writes it in MCAP.

    The type's own fields come first, then one `MSG: pkg/Type` block per nested type.

    Args:
        typename: The message type name.

    Returns:
        The schema text (comments are not kept).
    """
    return typestore().generate_msgdef(typename, ros_version=2)[0]


@functools.cache
def type_hash(typename: str) -> str:
    """Return the REP-2011 type hash (`RIHS01_<sha256 hex>`) of a message type.

    rosbags hashes `char` as its own type id, whereas rosidl maps `char` to `uint8` first, so
    `char` is replaced before hashing (this matters for rmw_dds_common/msg/Gid).

    Args:
        typename: The message type name.

    Returns:
        The type hash.
    """
    def uint8_for_char(desc: tuple) -> tuple:
        kind, arg = desc
        if kind == Nodetype.BASE:
            return (kind, ('uint8', 0)) if arg[0] == 'char' else desc
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            return (kind, (uint8_for_char(arg[0]), arg[1]))
        return desc

    shadow = Typestore()
    shadow.fielddefs = {
        name: (consts, [(fname, uint8_for_char(desc)) for fname, desc in fields])
        for name, (consts, fields) in typestore().fielddefs.items()
    }
    return shadow.hash_rihs01(typename)
