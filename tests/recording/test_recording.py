"""The MCAP recorder: rosbag2 conventions, field-exact read-back, lossless lockstep, crash safety.

Recordings come from ``EpisodeRunner``, a ``ChamberNode`` driven in process that records every
message it handles; a spy subclass of the recorder keeps every (topic, bytes) it was given so
the read-back can be compared with what was "published".
"""

from __future__ import annotations

import errno
import io
import json
import os
from pathlib import Path
import resource
import signal
import subprocess
import sys
import textwrap
import time

from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import MessageIndex
from mcap.stream_reader import breakup_chunk, StreamReader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
import zstandard

from growspace_sim import recording
from growspace_sim.agents import OracleAgent, play_episodes
from growspace_sim.core.config import SimConfig
from growspace_sim.node.episode_runner import EpisodeRunner
from growspace_sim.recording import McapRecorder, RecordingError
from growspace_sim.recording.chunk_writer import ChunkedWriter, record_bytes
from growspace_sim.replay import Bag, read_episodes, ReplayError, resimulate
from growspace_sim.ros import qos as ros_qos, types
from growspace_sim.ros.interface import TOPICS

ROOT = Path(__file__).resolve().parents[2]
PYTHONPATH = str(ROOT / 'src' / 'growspace_sim')


class SpyRecorder(McapRecorder):
    """Keeps a copy of every message written, in order."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.topic_of: dict[int, tuple[str, str]] = {}
        self.sent: list[tuple[str, str, bytes, int, int]] = []

    def add_channel(self, topic, typename, qos):
        channel = super().add_channel(topic, typename, qos)
        self.topic_of[channel] = (topic, typename)
        return channel

    def write_many(self, messages):
        messages = list(messages)
        super().write_many(messages)
        self.sent += [(*self.topic_of[channel], bytes(cdr), log_time_ns, publish_time_ns)
                      for channel, cdr, log_time_ns, publish_time_ns in messages]


def record(path: Path, challenge: str = 'control', episodes: int = 2, seed: int = 3,
           recorder_cls: type = SpyRecorder) -> tuple[McapRecorder, list[float]]:
    """Oracle episodes: the first as the node starts, the next ones by ResetRequest."""
    returns = []
    with recorder_cls(path) as rec:
        runner = EpisodeRunner(SimConfig(challenge=challenge), rec)
        agent = OracleAgent()
        for i in range(episodes):
            ret = play_episodes(runner, agent, [seed + i]).returns[0]
            returns.append(ret)
    return rec, returns


def plain_mcap_ros2(value):
    """mcap_ros2's decoded objects as nested dicts and lists."""
    if hasattr(value, '__slots__'):
        return {k: plain_mcap_ros2(getattr(value, k)) for k in value.__slots__}
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, list):
        return [plain_mcap_ros2(v) for v in value]
    return value


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    path = tmp_path_factory.mktemp('rec') / 'run.mcap'
    rec, returns = record(path)
    return path, rec, returns


@pytest.mark.slow
def test_read_back_with_rosbags_every_field_equal(recorded):
    path, rec, _ = recorded
    got = []
    with AnyReader([path]) as reader:
        for conn, log_time, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            got.append((conn.topic, conn.msgtype, bytes(raw), log_time, msg))
    assert len(got) == len(rec.sent) > 0
    # AnyReader sorts by time; the runner's stamps already put them in recorded order.
    for (topic, typename, cdr, log_time, _), (gtopic, gtype, graw, glog, gmsg) in zip(
            rec.sent, got):
        assert (gtopic, gtype, glog) == (topic, typename, log_time)
        assert graw == cdr
        assert json.dumps(types.to_plain(gmsg)) == json.dumps(
            types.to_plain(types.deserialize(cdr, typename)))


def test_read_back_with_mcap_ros2_every_field_equal(recorded):
    path, rec, _ = recorded
    with open(path, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        got = [(channel.topic, schema.name, message.data, message.log_time,
                message.publish_time, plain_mcap_ros2(decoded))
               for schema, channel, message, decoded in reader.iter_decoded_messages(
                   log_time_order=False)]
    assert len(got) == len(rec.sent)
    for (topic, typename, cdr, log_time, publish_time), g in zip(rec.sent, got):
        assert g[:5] == (topic, typename, cdr, log_time, publish_time)
        expected = types.to_plain(types.deserialize(cdr, typename))
        assert g[5] == expected


def test_file_follows_rosbag2_mcap_conventions(recorded):
    path, _, _ = recorded
    with open(path, 'rb') as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert {c.compression for c in summary.chunk_indexes} == {'zstd'}
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert channel.message_encoding == 'cdr'
            assert schema.encoding == 'ros2msg'
            assert schema.data.decode() == types.msgdef(schema.name)
            assert channel.metadata['topic_type_hash'] == types.type_hash(schema.name)
            topic = next(t for t in TOPICS if channel.topic.endswith(t.name.lstrip('/')))
            assert channel.metadata['offered_qos_profiles'] == ros_qos.offered_qos_yaml(
                topic.qos)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    info = meta[recording.METADATA_NAME]
    assert info['seed'] == '3'
    assert SimConfig.from_dict(json.loads(info['config'])) == SimConfig()
    assert float(info['chamber_width_m']) == SimConfig().chamber_width
    assert info['version'] and info['frame_id'] == 'chamber' and info['mode'] == 'lockstep'


def test_image_msg_is_foxglove_ready(recorded):
    path, _, _ = recorded
    with Bag(path) as bag:
        image = next(bag.messages(['/growspace/camera/image_raw'])).decode()
    assert (image.encoding, image.width, image.height, image.step) == ('rgb8', 84, 84, 252)


@pytest.mark.slow
def test_lockstep_full_speed_exactly_one_result_per_step(tmp_path):
    path = tmp_path / 'fast.mcap'
    start = time.perf_counter()
    record(path, episodes=4, recorder_cls=McapRecorder)
    assert time.perf_counter() - start < 60
    with Bag(path) as bag:
        results = [m.decode() for m in bag.messages(['/growspace/step_result'])]
        commands = [m.decode() for m in bag.messages(['/growspace/light/command'])]
    keys = [(int(r.reset_id), int(r.step)) for r in results]
    assert len(keys) == len(set(keys)) == 4 * 51
    for reset_id in range(4):  # 0: the node's first episode, at start
        assert sorted(s for r, s in keys if r == reset_id) == list(range(51))
    stepped = [int(r.step_id) for r in results if r.step > 0]
    # Lockstep ids count from 1 again after every reset.
    assert stepped == [int(c.step_id) for c in commands] == list(range(1, 51)) * 4


def test_refuses_to_overwrite(tmp_path):
    path = tmp_path / 'x.mcap'
    path.write_bytes(b'precious')
    with pytest.raises(RecordingError, match='exists already, not overwriting'):
        McapRecorder(path)
    assert path.read_bytes() == b'precious'
    with McapRecorder(path, overwrite=True):
        pass
    assert path.read_bytes()[:5] == b'\x89MCAP'


@pytest.mark.parametrize('where, message', [
    ('missing/dir/x.mcap', r'Cannot create recording .*does not exist'),
    ('.', 'is a directory'),
])
def test_bad_path_is_a_clear_error(tmp_path, where, message):
    with pytest.raises(RecordingError, match=message):
        McapRecorder(tmp_path / where)


@pytest.mark.skipif(not os.path.exists('/dev/full'), reason='needs /dev/full')
def test_full_disk_is_a_clear_error():
    with pytest.raises(RecordingError, match='No space left on device'):
        McapRecorder('/dev/full', overwrite=True)


def test_flush_with_sync_puts_the_file_on_the_disk(tmp_path, monkeypatch):
    # gantry_node's answered steps must survive a power cut, not only a kill (issue 31).
    from growspace_sim.recording import recorder as recorder_module

    synced: list[int] = []
    monkeypatch.setattr(recorder_module.os, 'fsync', synced.append)
    with McapRecorder(tmp_path / 's.mcap') as rec:
        channel = rec.add_channel('/a', types.STEP_RESULT, ros_qos.DEFAULT)
        rec.write(channel, b'\x00\x01\x00\x00', 0, 0)
        rec.flush()
        assert synced == []
        size = (tmp_path / 's.mcap').stat().st_size
        rec.write(channel, b'\x00\x01\x00\x00', 1, 1)
        rec.flush(sync=True)
        assert len(synced) == 1 and (tmp_path / 's.mcap').stat().st_size > size


def test_close_is_idempotent_and_later_writes_fail(tmp_path):
    rec = McapRecorder(tmp_path / 'c.mcap')
    channel = rec.add_channel('/a', types.STEP_RESULT, ros_qos.DEFAULT)
    assert rec.add_channel('/a', types.STEP_RESULT, ros_qos.DEFAULT) == channel
    rec.close()
    rec.close()
    with pytest.raises(RecordingError, match='closed'):
        rec.write(channel, b'\x00\x01\x00\x00', 0, 0)
    with pytest.raises(TypeError, match='must be str'):
        McapRecorder(tmp_path / 'd.mcap').add_metadata('m', {'k': 1})


def _cli(*args: str) -> list[str]:
    return [sys.executable, '-m', 'growspace_sim.tools.record', *args]


def _env() -> dict[str, str]:
    return {**os.environ, 'PYTHONPATH': PYTHONPATH}


def _wait_for_size(path: Path, size: int, proc: subprocess.Popen, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while not (path.exists() and path.stat().st_size >= size):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, 'the recorder wrote nothing'
        time.sleep(0.05)


@pytest.mark.slow
def test_sigterm_mid_episode_finishes_the_file(tmp_path):
    path = tmp_path / 'term.mcap'
    proc = subprocess.Popen(_cli('run', str(path), '--episodes', '100', '--realtime',
                                 '--rate-hz', '100'), env=_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    _wait_for_size(path, 40_000, proc)  # past the first chunk flush: mid-run
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert 'the recording was finished' in err
    with Bag(path) as bag:
        episodes = read_episodes(bag)
    assert episodes and episodes[0].n_steps > 0
    assert resimulate(path).ok


@pytest.mark.slow
@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
def test_sigkill_leaves_complete_chunks_recoverable(tmp_path):
    path, fixed = tmp_path / 'kill.mcap', tmp_path / 'fixed.mcap'
    proc = subprocess.Popen(_cli('run', str(path), '--episodes', '100', '--realtime',
                                 '--rate-hz', '100'), env=_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    _wait_for_size(path, 40_000, proc)
    _wait_for_size(path, path.stat().st_size + 1, proc)  # and a later chunk: killed mid-run
    proc.kill()
    proc.communicate(timeout=30)
    with pytest.raises(ReplayError, match='growspace-replay recover'):
        Bag(path)
    report = recording.recover(path, fixed)
    assert report.messages > 100 and not report.complete and report.chunks >= 1
    with Bag(fixed) as bag:
        assert bag.metadata[recording.METADATA_NAME]['seed'] == '0'
        assert read_episodes(bag)[0].n_steps > 0
    assert resimulate(fixed).ok
    with pytest.raises(RecordingError, match='exists already'):
        recording.recover(path, fixed)


@pytest.mark.slow
def test_disk_full_mid_run_keeps_the_chamber_running(tmp_path):
    # RLIMIT_FSIZE makes writes past 120 kB fail (EFBIG) as a full disk would (ENOSPC).
    path = tmp_path / 'full.mcap'
    script = textwrap.dedent(f"""
        import resource, signal
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (120_000, 120_000))
        from growspace_sim.agents import OracleAgent, play_episodes
        from growspace_sim.core.config import SimConfig
        from growspace_sim.node.episode_runner import EpisodeRunner
        from growspace_sim.recording import McapRecorder
        rec = McapRecorder({str(path)!r}, chunk_size=16_384)
        runner = EpisodeRunner(SimConfig(), rec)
        steps = play_episodes(runner, OracleAgent(), range(8)).steps
        rec.close()
        print(steps, runner.recording_error)
    """)
    out = subprocess.run([sys.executable, '-c', script], env=_env(), capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    steps, error = out.stdout.split(' ', 1)
    assert steps == '400'  # every episode ran to the end
    assert 'File too large' in error and 'growspace-replay recover' in error
    report = recording.recover(path, tmp_path / 'kept.mcap')
    assert report.messages > 0
    assert resimulate(tmp_path / 'kept.mcap').ok


@pytest.mark.slow
def test_atexit_finishes_an_unclosed_recording(tmp_path):
    path = tmp_path / 'exit.mcap'
    script = (f'from growspace_sim.recording import McapRecorder\n'
              f'from growspace_sim.ros import qos, types\n'
              f'r = McapRecorder({str(path)!r})\n'
              f'c = r.add_channel("/x", types.STEP_RESULT, qos.DEFAULT)\n'
              f'm = types.serialize(types.new(types.STEP_RESULT), types.STEP_RESULT)\n'
              f'r.write(c, m, 1, 1)\n'
              f'raise SystemExit(3)\n')
    out = subprocess.run([sys.executable, '-c', script], env=_env(), timeout=60)
    assert out.returncode == 3
    with Bag(path) as bag:
        assert [m.log_time for m in bag.messages()] == [1]


def test_stamps_and_sim_time(recorded):
    path, rec, _ = recorded
    clock = [(t, log) for topic, _, _, log, t in rec.sent if topic == '/clock']
    times = np.array([t for t, _ in clock])
    assert np.all(np.diff(times) == 100_000_000)  # one tick per step or reset at 10 Hz
    with Bag(path) as bag:
        assert bag.start_time < bag.end_time


def _records(raw: bytes) -> list:
    """The MCAP records of ``raw`` (no magic), chunks not opened."""
    found = []
    try:
        for record in StreamReader(io.BytesIO(raw), skip_magic=True, emit_chunks=True,
                                   validate_crcs=True).records:
            found.append(record)
    except EndOfFile:
        pass
    return found


def test_hand_packed_chunk_and_index_records_are_mcaps_own(recorded):
    # The writer packs Message, Chunk and MessageIndex records itself, for speed: they must be
    # byte for byte what mcap's record classes write.
    path, _, _ = recorded
    data = path.read_bytes()
    with open(path, 'rb') as stream:
        chunk_indexes = make_reader(stream).get_summary().chunk_indexes
    assert chunk_indexes
    for ci in chunk_indexes:
        start, end = ci.chunk_start_offset, ci.chunk_start_offset + ci.chunk_length
        (chunk,) = _records(data[start:end])
        assert record_bytes(chunk) == data[start:end]
        indexes = _records(data[end:end + ci.message_index_length])
        assert {type(r) for r in indexes} == {MessageIndex}
        assert record_bytes(*indexes) == data[end:end + ci.message_index_length]
        messages = breakup_chunk(chunk, validate_crc=True)
        assert record_bytes(*messages) == zstandard.ZstdDecompressor().decompress(
            chunk.data, ci.uncompressed_size)


def _no_file_writes() -> None:
    """In a child before exec: every write to a file fails (EFBIG), as on a full disk."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))


@pytest.mark.slow
def test_disk_full_at_start_leaves_no_empty_file_that_blocks_the_next_start(tmp_path):
    path = tmp_path / 'start.mcap'
    script = (f'from growspace_sim.recording import McapRecorder, RecordingError\n'
              f'try:\n    McapRecorder({str(path)!r})\n'
              f'except RecordingError as e:\n    print(e)\n')
    out = subprocess.run([sys.executable, '-c', script], env=_env(), capture_output=True,
                         text=True, timeout=60, preexec_fn=_no_file_writes)
    assert 'Cannot write recording' in out.stdout and 'File too large' in out.stdout, out
    assert not path.exists()  # the 0-byte file it created is gone
    with McapRecorder(path) as rec:  # the disk has room again: the same path works
        rec.add_channel('/x', types.STEP_RESULT, ros_qos.DEFAULT)
    assert path.stat().st_size > 0


def test_a_failed_start_never_removes_a_file_it_did_not_create(tmp_path, monkeypatch):
    path = tmp_path / 'theirs.mcap'
    path.write_bytes(b'')  # someone else's empty file: not ours to remove
    with pytest.raises(RecordingError, match='exists already'):
        McapRecorder(path)
    assert path.exists()

    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, 'No space left on device')
    monkeypatch.setattr(ChunkedWriter, 'start', no_space)
    with pytest.raises(RecordingError, match='No space left on device'):
        McapRecorder(path, overwrite=True)  # asked to replace it: it stays, emptied
    assert path.exists()
    with pytest.raises(RecordingError, match='No space left on device'):
        McapRecorder(tmp_path / 'mine.mcap')
    assert not (tmp_path / 'mine.mcap').exists()
