"""Wire compatibility of the message types: three independent CDR encoders must agree.

Encoders: rosbags (our codec, `types.serialize`, what the node publishes and records), rclpy's
`serialize_message` of the rosidl-generated classes (what every ROS 2 node sends), and
mcap_ros2's dynamic encoder fed with our MCAP schema text (`types.msgdef`).
"""

from __future__ import annotations

import re
from types import SimpleNamespace

import array
import importlib

from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.base import Nodetype

from growspace_sim.ros import types

# Golden REP-2011 hashes published by ROS 2 Jazzy (design/ros2-interop.md section 1.6).
GOLDEN_HASHES = {
    'sensor_msgs/msg/Image':
        'RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47',
    'std_msgs/msg/Header':
        'RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01',
    'builtin_interfaces/msg/Time':
        'RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197',
    # Contains char: only right if char is hashed as uint8, as rosidl does.
    'rmw_dds_common/msg/ParticipantEntitiesInfo':
        'RIHS01_91a0593bacdcc50ea9bdcf849a938b128412cc1ea821245c663bcd26f83c295e',
}
CAMERA_MEASUREMENT = 'growspace_msgs/msg/CameraMeasurement'
CAPTURE_REQUEST, CAPTURE_RESPONSE = ('growspace_msgs/srv/Capture_Request',
                                     'growspace_msgs/srv/Capture_Response')
OUR_TYPES = [types.LIGHT_COMMAND, types.PLANT_STATE, types.RESET_REQUEST, types.STEP_RESULT,
             types.RESET_SRV_REQUEST, types.RESET_SRV_RESPONSE, CAMERA_MEASUREMENT,
             CAPTURE_REQUEST, CAPTURE_RESPONSE]


def filled(typename: str, **given: object) -> dict:
    """Every field of a nested message: its defaults, then what is given."""
    return {**types.to_plain(types.new(typename)), **given}


def header(frame_id: str = 'chamber', sec: int = 1_700_000_123) -> dict:
    return {'stamp': {'sec': sec, 'nanosec': 987_654_321}, 'frame_id': frame_id}


# (id, type, plain value). Odd-length and unicode strings, empty and non-empty arrays, and
# float32 values that are exact in binary so decoded values compare equal.
SAMPLES = [
    ('light_beam', types.LIGHT_COMMAND, {
        'header': header(), 'step_id': 2**40 + 3, 'mode': 0, 'x': 0.4125, 'width': 0.0625}),
    ('light_continuous', types.LIGHT_COMMAND, {
        'header': header('châmbre_α'), 'step_id': 7, 'mode': 3, 'x': 0.1, 'z': 0.25,
        'width': 0.05, 'radius': 0.03, 'action': -2, 'continuous': [0.5, -1.0, 0.25]}),
    ('light_discrete', types.LIGHT_COMMAND, {
        'header': header(''), 'step_id': 1, 'mode': 2, 'action': 4, 'continuous': []}),
    ('plant_state', types.PLANT_STATE, {
        'header': header('abc'), 'step_id': 12, 'step': 11,
        'node_x': [0.5, 0.5, 0.52, 0.47, 0.3], 'node_z': [0.0, 0.1, 0.2, 0.19, 0.0],
        'parent': [-1, 0, 1, 1, -1], 'plant': [0, 0, 0, 0, 1], 'tips': [2, 3, 4],
        'branch_count': [3, 0]}),
    ('plant_state_empty', types.PLANT_STATE, {'header': header('x'), 'step': 0}),
    ('reset_request', types.RESET_REQUEST, {
        'header': header(), 'reset_id': 5, 'has_seed': True, 'seed': 2**63 + 5,
        'challenge': 'fairness', 'setting': 'hard'}),
    ('step_result', types.STEP_RESULT, {
        'header': header('cam'), 'step_id': 99, 'reset_id': 4, 'step': 49, 'reward': 0.8125,
        'plant_rewards': [0.125, 0.5, 0.75], 'terminated': False, 'truncated': True,
        'success': True, 'info': 'ok: ünïcødé 🌱'}),
    ('step_result_empty', types.STEP_RESULT, {'header': header(), 'info': ''}),
    ('reset_srv_request', types.RESET_SRV_REQUEST, {
        'has_seed': True, 'seed': 42, 'challenge': 'shape', 'setting': 'easy'}),
    ('reset_srv_response', types.RESET_SRV_RESPONSE, {
        'success': False, 'message': 'unknown challenge "x"', 'reset_id': 0}),
    ('camera_measurement', CAMERA_MEASUREMENT, {
        'header': header(), 'step_id': 3, 'ok': True, 'error_code': '', 'error': '',
        'reward': 0.625, 'plant_rewards': [0.625, 0.75], 'success': False,
        'markers_seen': [0, 1, 3], 'fit_held': True, 'fit_age': 2, 'fit_error_m': 0.00125,
        'exposure_mean': 0.5, 'saturated': 0.0, 'threshold': 0.25, 'contrast': 0.5,
        'plant_pixels': 4321, 'specks': 7, 'skeleton_pixels': [300, 12],
        'unattached_pixels': 3, 'tips': 5, 'tips_pruned': 1, 'leaves': 2, 'pixel_size_m': 0.002,
        'processing_s': 0.015625}),
    ('capture_request', CAPTURE_REQUEST, {
        'header': header(), 'step_id': 4, 'step': 4, 'config': '{"config": {}}',
        'light': filled(types.LIGHT_COMMAND, header=header(), mode=0, x=0.5, width=0.25),
        'has_point_target': True, 'target_x': 0.25, 'target_z': 0.75,
        'target_mask': [0, 1, 1, 0]}),
    ('capture_response_refused', CAPTURE_RESPONSE, {
        'observation': filled('sensor_msgs/msg/Image', header=header('chamber_camera'),
                              encoding='rgb8'),
        'plant': filled(types.PLANT_STATE, header=header(), step_id=4),
        'photo': filled('sensor_msgs/msg/CompressedImage', header=header('camera_optical'),
                        format='jpeg'),
        'measurement': filled(CAMERA_MEASUREMENT, header=header(), step_id=4, ok=False,
                              error_code='markers',
                              error='markers [0] of [0, 1, 2, 3] found')}),
    ('image_84x84_rgb8', 'sensor_msgs/msg/Image', {
        'header': header('camera_optical'), 'height': 84, 'width': 84, 'encoding': 'rgb8',
        'is_bigendian': 0, 'step': 252,
        'data': np.random.default_rng(3).integers(0, 256, 84 * 84 * 3, dtype=np.uint8)}),
    ('header', 'std_msgs/msg/Header', header('map')),
    ('clock', 'rosgraph_msgs/msg/Clock', {'clock': {'sec': 12, 'nanosec': 500_000_000}}),
]
IDS = [s[0] for s in SAMPLES]


def generated_class(typename: str) -> type:
    """The rosidl-generated Python class of ``pkg/msg/Name`` or ``pkg/srv/Name_Request``."""
    package, kind, name = typename.split('/')
    if kind == 'srv':
        service, part = name.rsplit('_', 1)
        return getattr(getattr(importlib.import_module(f'{package}.srv'), service), part)
    return getattr(importlib.import_module(f'{package}.msg'), name)


def generated(typename: str, value: dict) -> object:
    """A generated message holding a plain value (nested dicts for nested messages)."""
    msg = generated_class(typename)()
    fields = msg.get_fields_and_field_types()
    for name, item in value.items():
        if isinstance(item, dict):
            inner = fields[name].replace('/', '/msg/', 1)
            setattr(msg, name, generated(inner, item))
        else:
            setattr(msg, name, item)
    return msg


def plain(value: object) -> object:
    """Normalise decoded values of all three libraries to dicts and lists."""
    if hasattr(type(value), 'get_fields_and_field_types'):  # a generated rclpy message
        return {name: plain(getattr(value, name)) for name in value.get_fields_and_field_types()}
    if isinstance(value, (np.ndarray, array.array)):
        return value.tolist()
    if isinstance(value, SimpleNamespace):  # mcap_ros2 message classes keep fields in slots
        return {name: plain(getattr(value, name)) for name in type(value).__slots__}
    if isinstance(value, dict):
        return {name: plain(item) for name, item in value.items()}
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    return types.to_plain(value) if not isinstance(value, list) else [plain(v) for v in value]


@pytest.fixture(params=SAMPLES, ids=IDS)
def sample(request: pytest.FixtureRequest) -> tuple[str, object, dict]:
    _, typename, value = request.param
    return typename, types.from_plain(typename, value), value


def test_three_encoders_agree(sample: tuple[str, object, dict]) -> None:
    typename, msg, _ = sample
    ours = types.serialize(msg, typename)
    assert ours[:4] == types.CDR_LE_HEADER
    encoder = serialize_dynamic(typename, types.msgdef(typename))[typename]
    by_mcap = bytes(encoder(types.to_plain(msg)))
    assert ours == by_mcap
    # rclpy (Fast CDR) leaves alignment padding uninitialised and may end a message with up to
    # 4 more pad bytes, so its bytes can differ from ours in padding only: every differing byte
    # is a zero pad byte of ours, and each side decodes the other's bytes to the same message.
    by_rclpy = serialize_message(generated(typename, types.to_plain(msg)))
    assert 0 <= len(by_rclpy) - len(ours) <= 4
    differing = [i for i, (a, b) in enumerate(zip(ours, by_rclpy)) if a != b]
    assert all(ours[i] == 0 for i in differing), differing
    assert types.to_plain(types.deserialize(by_rclpy, typename)) == types.to_plain(msg)
    assert plain(deserialize_message(ours, generated_class(typename))) == types.to_plain(msg)


def test_round_trip_in_all_decoders(sample: tuple[str, object, dict]) -> None:
    typename, msg, value = sample
    data = types.serialize(msg, typename)
    expected = plain(value)
    full = types.to_plain(msg)
    assert {k: full[k] for k in expected} == expected  # from_plain kept what was given
    assert types.to_plain(types.deserialize(data, typename)) == full
    assert plain(deserialize_message(data, generated_class(typename))) == full
    decoder = generate_dynamic(typename, types.msgdef(typename))[typename]
    assert plain(decoder(data)) == full


def test_image_size_and_layout() -> None:
    _, typename, value = SAMPLES[IDS.index('image_84x84_rgb8')]
    data = types.serialize(types.from_plain(typename, value), typename)
    # encapsulation 4 + stamp 8 + frame_id 4+15 (+1 pad) + height, width 8 + encoding 4+5
    # + is_bigendian 1 (+2 pad) + step 4 + data length 4 + pixels 84*84*3, as rmw lays it out.
    assert data.endswith(bytes(value['data']))
    assert len(data) == 4 + 8 + 20 + 8 + 9 + 3 + 4 + 4 + 21168


@pytest.mark.parametrize('typename', OUR_TYPES)
def test_our_hashes_equal_rosbags(typename: str) -> None:
    assert types.type_hash(typename) == types.typestore().hash_rihs01(typename)
    assert re.fullmatch(r'RIHS01_[0-9a-f]{64}', types.type_hash(typename))


@pytest.mark.parametrize('typename', sorted(GOLDEN_HASHES))
def test_golden_hashes(typename: str) -> None:
    assert types.type_hash(typename) == GOLDEN_HASHES[typename]


@pytest.mark.parametrize('typename', OUR_TYPES + ['sensor_msgs/msg/Image'])
def test_msgdef_parses_back_to_the_same_type(typename: str) -> None:
    text = types.msgdef(typename)
    blocks = text.split('=' * 80 + '\n')
    parsed = get_types_from_msg(blocks[0], 'check_msgs/msg/Top')
    assert parsed['check_msgs/msg/Top'][1] == types.typestore().fielddefs[typename][1]
    for block in blocks[1:]:
        name_line, body = block.split('\n', 1)
        pkg, short = name_line.removeprefix('MSG: ').split('/')
        full = f'{pkg}/msg/{short}'
        assert get_types_from_msg(body, full)[full][1] == types.typestore().fielddefs[full][1]


def test_constants_and_enum_values() -> None:
    cls = types.msg_class(types.LIGHT_COMMAND)
    assert (cls.MODE_BEAM, cls.MODE_SPOT, cls.MODE_DISCRETE, cls.MODE_CONTINUOUS) == (0, 1, 2, 3)


def test_no_char_and_every_field_documented() -> None:
    root = types.msgs_dir()
    files = sorted((root / 'msg').glob('*.msg')) + sorted((root / 'srv').glob('*.srv'))
    assert len(files) == 7
    for path in files:
        for line in path.read_text(encoding='utf-8').splitlines():
            code = line.split('#', 1)[0].strip()
            if not code or code == '---':
                continue
            assert not re.match(r'char\b', code), f'{path.name}: char has no portable hash'
            assert '#' in line, f'{path.name}: field without a comment: {line!r}'

    def walk(desc: tuple) -> None:
        kind, arg = desc
        if kind == Nodetype.BASE:
            assert arg[0] != 'char'
        elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            walk(arg[0])
    for typename in OUR_TYPES:
        for _, desc in types.typestore().fielddefs[typename][1]:
            walk(desc)


@pytest.mark.parametrize('index', range(len(SAMPLES)), ids=IDS)
def test_every_truncation_is_a_cdr_error(index: int) -> None:
    _, typename, value = SAMPLES[index]
    data = types.serialize(types.from_plain(typename, value), typename)
    step = max(1, len(data) // 64)  # the image has 21k prefixes; a sample of them suffices
    for n in [*range(0, len(data) - 1, step), len(data) - 1]:
        with pytest.raises(types.CdrError):
            types.deserialize(data[:n], typename)
    assert types.to_plain(types.deserialize(data + bytes(7), typename)) == types.to_plain(
        types.deserialize(data, typename))  # pad bytes, as rmw_fastrtps may send
    with pytest.raises(types.CdrError, match='8 bytes after the message'):
        types.deserialize(data + bytes(8), typename)
    with pytest.raises(types.CdrError, match='XCDR1'):
        types.deserialize(b'\x00\x07\x00\x00' + data[4:], typename)


def test_new_fills_defaults_and_checks_fields() -> None:
    msg = types.new(types.PLANT_STATE, node_x=[1, 2])
    assert msg.node_x.dtype == np.float64 and msg.parent.dtype == np.int32
    assert msg.header.frame_id == '' and msg.step == 0
    with pytest.raises(TypeError, match='no field'):
        types.new(types.PLANT_STATE, nodes=[])


@pytest.mark.parametrize('values, field, allowed', [
    ('{step_id: -1}', 'step_id = -1', r'an integer in \[0, 18446744073709551615\] \(uint64\)'),
    ('{step_id: 18446744073709551616}', 'step_id = 18446744073709551616', 'uint64'),
    ('{x: abc}', "x = 'abc'", r'a number \(float64\)'),
    ('{mode: true}', 'mode = True', r'an integer in \[0, 255\] \(uint8\)'),
    ('{action: 2.5}', 'action = 2.5', r'\(int32\)'),
    ('{header: {stamp: {sec: 1.5}}}', 'header.stamp.sec = 1.5', r'\(int32\)'),
    ('{header: {frame_id: 7}}', 'header.frame_id = 7', 'a string'),
    ('{header: 3}', 'header = 3', 'a mapping of the fields of std_msgs/msg/Header'),
    ('{continuous: [0.5, .nan, 1.0e+39]}', r'continuous\[2\] = 1e\+39', r'\|x\| <= 3.4e38'),
    ('{continuous: 0.5}', 'continuous = 0.5', 'a list'),
])
def test_pub_names_the_field_the_value_and_what_is_allowed(capsys, values, field, allowed):
    from growspace_sim.tools import pub  # noqa: PLC0415

    assert pub.main(['/light/command', types.LIGHT_COMMAND, values, '--wait', '0']) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert re.search(rf'^pub: {field} is not allowed; expected .*{allowed}', err), err


def test_from_plain_accepts_every_value_its_field_can_hold():
    msg = types.from_plain(types.LIGHT_COMMAND, {
        'step_id': 2 ** 64 - 1, 'mode': 255, 'action': -2 ** 31, 'x': 1, 'z': -0.5,
        'continuous': [-1, 0.5, float('nan'), float('inf')],
        'header': {'stamp': {'sec': -1, 'nanosec': 2 ** 32 - 1}, 'frame_id': 'chamber'}})
    back = types.deserialize(types.serialize(msg, types.LIGHT_COMMAND), types.LIGHT_COMMAND)
    assert (back.step_id, back.mode, back.action, back.x) == (2 ** 64 - 1, 255, -2 ** 31, 1.0)
    assert back.header.stamp.nanosec == 2 ** 32 - 1 and back.continuous.tolist()[:2] == [-1, 0.5]
