"""The Cyclone DDS transport between processes, over loopback only, on a random domain."""

from __future__ import annotations

import json
import os
from pathlib import Path
import random
import subprocess
import sys
import time
from typing import Iterator
import xml.etree.ElementTree as ET

from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.qos import Policy
import pytest

from growspace_sim.ros import dds, qos, types

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config' / 'cyclonedds.xml'
NAMESPACE = '/gs_test'
KEEP_ALL = qos.QosProfile(history='keep_all')  # lossless, so 'exactly once' is well defined
CHILD_TIMEOUT_S = 30

# The publisher process: reads [typename, topic, plain message] lines as JSON from stdin and
# publishes them once both subscriptions are matched.
PUBLISHER = """
import json, sys
from growspace_sim.ros import dds, qos, types
work = json.load(sys.stdin)
with dds.DdsContext('talker', sys.argv[1]) as ctx:
    pubs = {t: ctx.create_publisher(tn, t, qos.QosProfile(history='keep_all'))
            for tn, t, _ in work}
    assert all(p.wait_for_subscribers(1, 10.0) for p in pubs.values()), 'no subscriber'
    for tn, t, value in work:
        pubs[t].publish(types.from_plain(tn, value))
    assert all(p.wait_for_acks(10.0) for p in pubs.values()), 'not acknowledged'
print('DONE', flush=True)
"""

# The late joiner: reads ros_discovery_info and prints the snapshots of one participant.
DISCOVERY_READER = """
import json, sys, time
from growspace_sim.ros import dds, qos, types
gid = bytes.fromhex(sys.argv[1])
with dds.DdsContext('spy', '/') as ctx:
    sub = ctx.create_subscription(dds.PARTICIPANT_INFO, dds.DISCOVERY_TOPIC,
                                  qos.DISCOVERY_INFO_READER)
    deadline = time.monotonic() + 20.0
    seen_empty = False
    while not seen_empty and time.monotonic() < deadline:
        sub.wait(0.5)
        for _, msg in sub.take():
            plain = types.to_plain(msg)
            if bytes(plain['gid']['data']) == gid:
                print(json.dumps(plain), flush=True)
                seen_empty = not plain['node_entities_info_seq']
"""


@pytest.fixture(scope='module', autouse=True)
def loopback_env() -> Iterator[dict[str, str]]:
    """Loopback-only Cyclone config from config/ and a random domain, for us and children."""
    saved = {k: os.environ.get(k) for k in ('CYCLONEDDS_URI', 'ROS_DOMAIN_ID', 'PYTHONPATH')}
    os.environ['CYCLONEDDS_URI'] = CONFIG.as_uri()
    os.environ['ROS_DOMAIN_ID'] = str(random.SystemRandom().randint(100, 200))
    os.environ['PYTHONPATH'] = os.pathsep.join(
        [str(ROOT / 'src' / 'growspace_sim')] + ([saved['PYTHONPATH']] if saved['PYTHONPATH']
                                                 else []))
    yield dict(os.environ)
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


def spawn(code: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, '-c', code, *args], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(proc: subprocess.Popen) -> tuple[str, str]:
    try:
        return proc.communicate(timeout=CHILD_TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def light(i: int) -> dict:
    return {'header': {'stamp': {'sec': i, 'nanosec': 7 * i}, 'frame_id': 'chamber'},
            'step_id': i + 1, 'mode': i % 4, 'x': 0.01 * i, 'z': 0.5, 'width': 0.125,
            'radius': 0.0625, 'action': i % 5 - 2, 'continuous': [0.5, -0.25][: i % 3]}


def result(i: int) -> dict:
    return {'header': {'stamp': {'sec': i, 'nanosec': 1}, 'frame_id': 'c' * (i % 5)},
            'step_id': i + 1, 'reset_id': 3, 'step': i, 'reward': i / 128,
            'plant_rewards': [i / 256] * (i % 3), 'terminated': i % 7 == 0,
            'truncated': i == 49, 'success': i % 2 == 1, 'info': 'pousse 🌱' * (i % 2)}


def test_config_file_equals_the_built_in_default() -> None:
    def tree(element: ET.Element) -> tuple:
        tag = element.tag.split('}')[-1]  # drop the xmlns
        return (tag, element.attrib, (element.text or '').strip(),
                [tree(child) for child in element])
    assert tree(ET.parse(CONFIG).getroot()) == tree(ET.fromstring(dds.LOOPBACK_CONFIG))
    text = CONFIG.read_text()
    assert '<AllowMulticast>false</AllowMulticast>' in text and 'name="lo"' in text


def test_default_config_is_applied_when_unset(loopback_env: dict[str, str]) -> None:
    env = {k: v for k, v in loopback_env.items() if k != 'CYCLONEDDS_URI'}
    code = ('import os\nfrom growspace_sim.ros import dds\nwith dds.DdsContext("n"): pass\n'
            'print(os.environ["CYCLONEDDS_URI"] == dds.LOOPBACK_CONFIG)')
    out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True, text=True,
                         timeout=CHILD_TIMEOUT_S)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == 'True'


def test_two_processes_every_message_exactly_once() -> None:
    n = 60
    work = [[types.LIGHT_COMMAND, 'light/command', light(i)] for i in range(n)]
    work += [[types.STEP_RESULT, 'step_result', result(i)] for i in range(n)]
    with dds.DdsContext('listener', NAMESPACE) as ctx:
        subs = {t: ctx.create_subscription(tn, t, KEEP_ALL) for tn, t in
                [(types.LIGHT_COMMAND, 'light/command'), (types.STEP_RESULT, 'step_result')]}
        child = spawn(PUBLISHER, NAMESPACE)
        child.stdin.write(json.dumps(work))
        child.stdin.close()
        child.stdin = None  # so that communicate() does not flush it again
        got: dict[str, list] = {t: [] for t in subs}
        deadline = time.monotonic() + CHILD_TIMEOUT_S
        while sum(map(len, got.values())) < 2 * n and time.monotonic() < deadline:
            for topic, sub in subs.items():
                sub.wait(0.05)
                got[topic] += sub.take()
        out, err = finish(child)
        time.sleep(0.2)  # anything duplicated would have arrived by now
        for topic, sub in subs.items():
            got[topic] += sub.take()
    assert child.returncode == 0 and 'DONE' in out, err
    for topic, typename, make in [('light/command', types.LIGHT_COMMAND, light),
                                  ('step_result', types.STEP_RESULT, result)]:
        decoded = [msg for _, msg in got[topic]]
        assert not [m for m in decoded if isinstance(m, types.CdrError)]
        assert [types.to_plain(m) for m in decoded] == [
            types.to_plain(types.from_plain(typename, make(i))) for i in range(n)]
        # The received bytes are what the publisher serialised (plus DDS 4-byte padding).
        data = got[topic][-1][0]
        expected = types.serialize(types.from_plain(typename, make(n - 1)), typename)
        assert data[:len(expected)] == expected and len(data) - len(expected) < 4


def test_dds_names_types_and_qos_seen_by_a_remote_reader() -> None:
    with dds.DdsContext('sim', NAMESPACE) as sim, dds.DdsContext('probe') as probe:
        sim.create_publisher(types.STEP_RESULT, 'step_result')
        sim.create_publisher('sensor_msgs/msg/Image', '~/image', qos.SENSOR_DATA)
        reader = BuiltinDataReader(probe.participant, BuiltinTopicDcpsPublication)
        found: dict[str, object] = {}
        deadline = time.monotonic() + 10
        while len(found) < 3 and time.monotonic() < deadline:
            for sample in reader.take(N=32):
                if sample.participant_key.bytes == sim.gid:
                    found[sample.topic_name] = sample
            time.sleep(0.02)
    assert set(found) == {'rt/gs_test/step_result', 'rt/gs_test/sim/image', 'ros_discovery_info'}
    step = found['rt/gs_test/step_result']
    assert step.type_name == 'growspace_msgs::msg::dds_::StepResult_'
    assert step.qos[Policy.Userdata].data == (
        f'typehash={types.type_hash(types.STEP_RESULT)};'.encode())
    assert step.qos[Policy.DataRepresentation].use_cdrv0_representation
    assert not step.qos[Policy.DataRepresentation].use_xcdrv2_representation
    image = found['rt/gs_test/sim/image']
    assert image.type_name == 'sensor_msgs::msg::dds_::Image_'
    assert image.qos[Policy.Reliability] == Policy.Reliability.BestEffort
    disc = found['ros_discovery_info']
    assert disc.type_name == 'rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_'
    assert disc.qos[Policy.Durability] == Policy.Durability.TransientLocal


def test_malformed_samples_come_back_as_errors() -> None:
    good = types.serialize(types.new(types.STEP_RESULT, step_id=5, info='hello'),
                           types.STEP_RESULT)
    bad_utf8 = good[:-6] + b'\xff\xfe' + good[-4:]  # Cyclone passes it, UTF-8 decoding fails
    trailing = good + bytes(12)  # longer than the type: not what any rmw writes
    with dds.DdsContext('a', NAMESPACE) as a, dds.DdsContext('b', NAMESPACE) as b:
        sub = b.create_subscription(types.STEP_RESULT, 'bad', KEEP_ALL)
        pub = a.create_publisher(types.STEP_RESULT, 'bad', KEEP_ALL)
        assert pub.wait_for_subscribers(1, 10.0)
        for data in (bad_utf8, trailing, good):
            pub.publish_raw(data)
        # Cyclone itself refuses bytes that do not fit the type's layout.
        with pytest.raises(dds.DdsError, match='valid XCDR1'):
            pub.publish_raw(good[:20])
        assert pub.wait_for_acks(5.0)
        got = []
        deadline = time.monotonic() + 10
        while len(got) < 3 and time.monotonic() < deadline:
            sub.wait(0.1)
            got += sub.take()
    assert len(got) == 3
    assert isinstance(got[0][1], types.CdrError) and 'utf-8' in str(got[0][1])
    assert isinstance(got[1][1], types.CdrError) and 'size mismatch' in str(got[1][1])
    assert got[2][1].step_id == 5 and got[2][1].info == 'hello'


def test_take_reports_truncated_bytes_without_raising(monkeypatch: pytest.MonkeyPatch) -> None:
    # A remote writer that skips Cyclone's checks could send these; take must survive them.
    good = types.serialize(types.new(types.LIGHT_COMMAND, continuous=[0.5]), types.LIGHT_COMMAND)
    raw = [good[:n] for n in (0, 3, 4, 9, len(good) - 2)] + [good]
    with dds.DdsContext('t', NAMESPACE) as ctx:
        sub = ctx.create_subscription(types.LIGHT_COMMAND, 'truncated')
        monkeypatch.setattr(dds, '_take_raw', lambda reader, max_n: raw[:max_n])
        got = sub.take()
    assert [isinstance(m, types.CdrError) for _, m in got] == [True] * 5 + [False]
    assert [d for d, _ in got] == raw


def test_spin_once_runs_callbacks_and_drops_malformed() -> None:
    received = []
    with dds.DdsContext('a', NAMESPACE) as a, dds.DdsContext('b', NAMESPACE) as b:
        b.create_subscription(types.RESET_REQUEST, 'reset', KEEP_ALL, received.append)
        pub = a.create_publisher(types.RESET_REQUEST, 'reset', KEEP_ALL)
        assert pub.wait_for_subscribers(1, 10.0)
        good = types.serialize(types.new(types.RESET_REQUEST, reset_id=1, challenge='x'),
                               types.RESET_REQUEST)
        pub.publish_raw(good + bytes(8))
        pub.publish(types.new(types.RESET_REQUEST, reset_id=2, seed=3, has_seed=True))
        deadline = time.monotonic() + 10
        while not received and time.monotonic() < deadline:
            b.spin_once(0.1)
    assert [(m.reset_id, m.seed) for m in received] == [(2, 3)]


def test_discovery_info_reaches_a_late_joiner_and_is_emptied_on_close() -> None:
    ctx = dds.DdsContext('growspace_sim', NAMESPACE)
    try:
        # Publisher last: the snapshot must be republished on every new entity.
        sub = ctx.create_subscription(types.LIGHT_COMMAND, 'light/command')
        pub = ctx.create_publisher(types.STEP_RESULT, 'step_result')
        gids = ctx.gid, pub.gid, sub.gid
        time.sleep(0.2)  # the reader joins after the snapshots were written
        child = spawn(DISCOVERY_READER, ctx.gid.hex())
        first = json.loads(child.stdout.readline() or 'null')
        ctx.close()
        ctx.close()  # idempotent
        out, err = finish(child)
    finally:
        ctx.close()
    assert first is not None, err
    assert first['gid']['data'] == list(gids[0])
    [node] = first['node_entities_info_seq']
    assert (node['node_namespace'], node['node_name']) == (NAMESPACE, 'growspace_sim')
    assert [g['data'] for g in node['writer_gid_seq']] == [list(gids[1])]
    assert [g['data'] for g in node['reader_gid_seq']] == [list(gids[2])]
    last = json.loads(out.strip().splitlines()[-1])
    assert last['node_entities_info_seq'] == []


def test_closed_context_refuses_new_endpoints() -> None:
    ctx = dds.DdsContext('short_lived', NAMESPACE)
    ctx.close()
    with pytest.raises(dds.DdsError, match='closed'):
        ctx.create_publisher(types.STEP_RESULT, 'x')
