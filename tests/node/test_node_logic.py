"""The chamber node's logic through the in-memory transport (everything above the seam)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import growspace_sim
from growspace_sim.core.config import SimConfig
from growspace_sim.envs.env import GrowSpaceEnv
from growspace_sim.node.chamber_node import EPISODE_OVER, INPUTS, OUTPUTS, ChamberNode
from growspace_sim.node.fake import FakeTransport
from growspace_sim.node.params import NodeParams
from growspace_sim.ros import convert
from growspace_sim.ros import types

SEED = 1234


def command(step_id: int, mode: int = convert.MODE_DISCRETE, **fields) -> object:
    return types.new(types.LIGHT_COMMAND, step_id=step_id, mode=mode, **fields)


def reset(reset_id: int, **fields) -> object:
    return types.new(types.RESET_REQUEST, reset_id=reset_id, **fields)


def image(msg: object) -> np.ndarray:
    return convert.image_from_msg(msg)


def make(cfg: SimConfig | None = None, recorder: object = None, **params) -> tuple:
    transport = FakeTransport(namespace='/chamber1')
    params.setdefault('seed', SEED)
    node = ChamberNode(transport, cfg or SimConfig(), NodeParams(**params), recorder)
    return transport, node


def last_result(transport: FakeTransport) -> object:
    return transport.messages('step_result')[-1]


def test_startup_reset_publishes_step_zero_outputs() -> None:
    transport, node = make()
    env = GrowSpaceEnv()
    obs, _ = env.reset(seed=SEED)
    for _, topic, _, _ in OUTPUTS:
        assert len(transport.messages(topic)) == 1, topic
    assert np.array_equal(image(transport.messages('camera/image_raw')[0]), obs)
    result = last_result(transport)
    assert (result.step, result.step_id, result.reset_id, result.info) == (0, 0, 0, '')
    config = json.loads(transport.messages('chamber/config')[0].data)
    assert config['seed'] == SEED and config['version'] == growspace_sim.__version__
    assert config['config']['challenge'] == 'control' and config['mode'] == 'lockstep'
    assert SimConfig.from_dict(config['config']) == node.cfg
    # Namespaced, relative topics; /clock stays absolute.
    assert '/chamber1/step_result' in transport.published and '/clock' in transport.published


def test_random_seed_is_drawn_and_published() -> None:
    transport, node = make(seed=-1)
    config = json.loads(transport.messages('chamber/config')[0].data)
    assert isinstance(config['seed'], int) and config['seed'] >= 0
    assert node.seed == config['seed']


def test_lockstep_matches_in_process_env_bit_for_bit() -> None:
    transport, node = make()
    env = GrowSpaceEnv()
    env.reset(seed=SEED)
    rng = np.random.default_rng(5)
    for step_id in range(1, 51):
        action = int(rng.integers(5))
        before = {k: len(transport.messages(t)) for k, t, _, _ in OUTPUTS}
        transport.inject('light/command', command(step_id, action=action))
        obs, reward, terminated, truncated, info = env.step(action)
        for key, topic, _, _ in OUTPUTS:
            expected = 0 if key == 'config' else 1
            assert len(transport.messages(topic)) == before[key] + expected, (step_id, topic)
        result = last_result(transport)
        assert (result.step_id, result.step, result.truncated) == (step_id, step_id, truncated)
        assert result.reward == reward and not result.terminated and result.info == ''
        assert np.array_equal(image(transport.messages('camera/image_raw')[-1]), obs)
        state = transport.messages('plant/state')[-1]
        tips = np.stack([state.node_x[state.tips], state.node_z[state.tips]], axis=1)
        assert np.array_equal(tips, info['tips'][0]) and state.step_id == step_id
        light = transport.messages('light/state')[-1]
        assert (light.x, light.width, light.step_id) == (info['light']['x'],
                                                         info['light']['width'], step_id)
        stamps = {convert.to_ns(transport.messages(t)[-1].header.stamp) for t in
                  ('camera/image_raw', 'plant/state', 'light/state', 'step_result')}
        assert stamps == {node.sim_time_ns} == {
            convert.to_ns(transport.messages('/clock')[-1].clock)}
    assert truncated


def test_step_result_is_published_last() -> None:
    transport, node = make()
    order = []
    for key, topic, _, _ in OUTPUTS:
        name = transport.resolve(topic)
        original = node._pubs[key]
        node._pubs[key] = lambda msg, original=original, name=name: (
            order.append(name), original(msg))[1]
    transport.inject('light/command', command(1, action=2))
    assert order[-1] == '/chamber1/step_result' and len(order) == 5


def test_duplicate_late_and_zero_step_ids_are_answered_with_an_error_and_a_warning() -> None:
    transport, node = make()
    transport.inject('light/command', command(5, action=1))
    count = len(transport.messages('step_result'))
    for step_id in (5, 3, 0):  # two kinds of warning: neither hides the other
        transport.inject('light/command', command(step_id, action=1))
        result = last_result(transport)
        assert (result.step_id, result.step) == (step_id, 1)
        assert result.info.startswith(f'error: step_id = {step_id} ') and '> 5' in result.info
    assert len(transport.messages('step_result')) == count + 3
    assert 'step_id = 5 is a duplicate' in transport.warnings[-2]
    assert 'step_id = 0' in transport.warnings[-1] and 'realtime' in transport.warnings[-1]
    transport.inject('light/command', command(6, action=1))
    assert last_result(transport).step_id == 6 and last_result(transport).step == 2
    assert last_result(transport).info == ''


def test_a_gap_in_step_ids_is_reported() -> None:
    transport, node = make()
    transport.inject('light/command', command(1, action=1))
    transport.inject('light/command', command(4, action=1))
    assert last_result(transport).step == 2
    assert 'step_ids 2..3 never arrived' in transport.warnings[-1]


def test_a_clamped_absolute_command_is_reported_naming_field_and_value() -> None:
    transport, node = make()
    transport.inject('light/command', command(1, mode=convert.MODE_BEAM, x=5.0, width=1e300))
    result = last_result(transport)
    assert result.info == '' and result.step == 1
    assert any('x = 5.0 m' in w and 'clamped' in w for w in transport.warnings)
    assert any('width = 1e+300 m' in w for w in transport.warnings)


def test_warnings_are_throttled_per_field() -> None:
    transport, node = make()
    for _ in range(100):
        transport.inject('light/command', command(0))
    assert len(transport.warnings) == 1
    transport.time_s += 10
    transport.inject('light/command', command(0))
    assert len(transport.warnings) == 2 and '99 similar warnings suppressed' in \
        transport.warnings[-1]


def test_command_after_the_episode_is_answered_without_a_step() -> None:
    transport, node = make(SimConfig(episode_length=3))
    for step_id in (1, 2, 3):
        transport.inject('light/command', command(step_id, action=2))
    assert last_result(transport).truncated
    images = len(transport.messages('camera/image_raw'))
    transport.inject('light/command', command(4, action=2))
    result = last_result(transport)
    expected = (4, 3, True, EPISODE_OVER)
    assert (result.step_id, result.step, result.truncated, result.info) == expected
    assert len(transport.messages('camera/image_raw')) == images


@pytest.mark.parametrize(('fields', 'named'), [
    ({'mode': convert.MODE_BEAM, 'x': math.nan, 'width': 0.1}, 'x'),
    ({'mode': convert.MODE_BEAM, 'x': 0.3, 'width': math.inf}, 'width'),
    ({'mode': 9}, 'mode'),
    ({'mode': convert.MODE_SPOT, 'x': 0.3, 'z': 0.5, 'radius': 0.1}, 'mode'),
    ({'mode': convert.MODE_DISCRETE, 'action': 5}, 'action'),
    ({'mode': convert.MODE_DISCRETE, 'action': -1}, 'action'),
    ({'mode': convert.MODE_CONTINUOUS, 'continuous': [0.5]}, 'continuous'),
    ({'mode': convert.MODE_CONTINUOUS, 'continuous': [0.5, 2.0]}, 'continuous'),
    ({'mode': convert.MODE_CONTINUOUS, 'continuous': [math.nan, 0.0]}, 'continuous'),
])
def test_bad_command_gets_an_error_result_and_no_step(fields: dict, named: str) -> None:
    transport, node = make()
    light = node.sim.chamber.light.copy()
    transport.inject('light/command', command(1, **fields))
    result = last_result(transport)
    assert result.step_id == 1 and result.step == 0 and result.info.startswith('error: ')
    assert named in result.info and math.isfinite(result.reward)
    assert named in transport.warnings[-1] and 'step_id 1' in transport.warnings[-1]
    assert node.sim.chamber.light == light and node.sim.chamber.steps == 0
    transport.inject('light/command', command(2, action=1))  # the node goes on
    assert last_result(transport).step == 1 and last_result(transport).info == ''


@pytest.mark.parametrize(('topic', 'msg', 'named'), [
    ('light/command', command(1, convert.MODE_CONTINUOUS, continuous=np.full(100_000, 0.5)),
     'continuous = array('),
    ('light/command', command(1, convert.MODE_CONTINUOUS, continuous=np.full(100_000, np.nan)),
     'continuous = array('),
    ('reset', reset(1, challenge='c' * 100_000), "challenge = 'ccc"),
    # The setting is checked against the challenge's settings, by SimConfig.
    ('reset', reset(1, setting='s' * 100_000),
     "setting must be one of ('easy', 'hard'), got 'sss"),
])
def test_an_error_reply_quotes_a_huge_input_briefly(topic: str, msg: object, named: str) -> None:
    transport, _ = make()
    sent = transport.inject(topic, msg)
    (result, cdr), = transport.published['/chamber1/step_result'][1:]
    assert len(sent) > 100_000 and result.info.startswith(f'error: {named}')
    assert len(result.info) < 500 and len(cdr) < 1_000  # the error reply, not an echo
    assert len(transport.warnings[-1]) < 600


def test_absolute_command_is_clamped_and_reported_on_light_state() -> None:
    transport, node = make()
    transport.inject('light/command', command(1, convert.MODE_BEAM, x=99.0, width=0.0))
    light = transport.messages('light/state')[-1]
    cfg = node.cfg
    assert light.mode == convert.MODE_BEAM
    assert light.width == pytest.approx(cfg.width_m(cfg.light_width_min))
    assert light.x == pytest.approx(cfg.chamber_width - light.width / 2)


def test_reset_twice_then_step_and_seeded_reset_reproduces() -> None:
    transport, node = make()
    transport.inject('light/command', command(1, action=1))
    transport.inject('reset', reset(7, has_seed=True, seed=99))
    transport.inject('reset', reset(8, has_seed=True, seed=99))
    first = last_result(transport)
    assert (first.reset_id, first.step, first.step_id) == (8, 0, 0)
    transport.inject('light/command', command(1, action=0))  # ids count again after a reset
    env = GrowSpaceEnv()
    env.reset(seed=99)
    obs, reward, *_ = env.step(0)
    assert last_result(transport).reward == reward and last_result(transport).reset_id == 8
    assert np.array_equal(image(transport.messages('camera/image_raw')[-1]), obs)
    assert len(transport.messages('chamber/config')) == 3


def test_unseeded_reset_continues_the_stream_across_a_challenge_switch() -> None:
    transport, node = make()
    transport.inject('reset', reset(1, challenge='fairness'))
    config = json.loads(transport.messages('chamber/config')[-1].data)
    assert config['seed'] is None and config['reset_id'] == 1  # null: the stream continued
    assert config['config']['challenge'] == 'fairness'
    # The same stream in a plain Simulation: reset with the seed, then again unseeded.
    from growspace_sim.simulation import Simulation

    sim = Simulation(SimConfig())
    sim.reset(seed=SEED)
    switched = sim.with_config(SimConfig(challenge='fairness'))
    switched.reset()
    assert np.array_equal(image(transport.messages('camera/image_raw')[-1]), switched.observe())


def test_challenge_switch_and_invalid_reset() -> None:
    transport, node = make()
    transport.inject('reset', reset(3, challenge='shape', setting='hard', has_seed=True, seed=1))
    assert node.cfg.challenge == 'shape' and node.sim.chamber.light.spot
    assert image(transport.messages('camera/image_raw')[-1]).shape == (28, 28, 3)
    config = json.loads(transport.messages('chamber/config')[-1].data)
    assert config['config']['challenge'] == 'shape' and config['config']['setting'] == 'hard'
    transport.inject('light/command', command(1, convert.MODE_SPOT, x=0.4, z=0.5, radius=0.1))
    assert last_result(transport).info == ''
    before = (node.cfg, node.sim.chamber.steps, len(transport.messages('camera/image_raw')))
    transport.inject('reset', reset(4, challenge='tennis'))
    result = last_result(transport)
    assert result.reset_id == 4 and 'challenge' in result.info and 'tennis' in result.info
    assert (node.cfg, node.sim.chamber.steps, len(transport.messages('camera/image_raw'))) == \
        before
    assert 'challenge' in transport.warnings[-1]


def test_reset_service_like_rclpy() -> None:
    transport, node = make()
    handler = transport.services['reset']
    ok = handler(types.new(types.RESET_SRV_REQUEST, has_seed=True, seed=5, challenge='fairness'))
    assert ok.success and ok.reset_id == node.reset_id and node.cfg.challenge == 'fairness'
    bad = handler(types.new(types.RESET_SRV_REQUEST, setting='medium'))
    assert not bad.success and 'setting' in bad.message


def test_realtime_ticks_with_a_fake_clock_and_auto_resets() -> None:
    transport, node = make(SimConfig(episode_length=4), mode='realtime', rate_hz=20.0)
    assert transport.advance(0.049) == 0
    transport.inject('light/command', command(0, action=0))
    transport.inject('light/command', command(0, action=1))  # last wins
    x0 = node.sim.chamber.light.x
    assert transport.advance(0.002) == 1
    assert node.sim.chamber.light.x == pytest.approx(x0 + node.cfg.light_step_m)
    assert last_result(transport).step == 1 and last_result(transport).step_id == 0
    transport.advance(0.15)  # steps 2..4: the episode ends
    assert last_result(transport).truncated
    resets = len(transport.messages('chamber/config'))
    transport.advance(0.05)  # auto reset, continuing the random stream
    assert len(transport.messages('chamber/config')) == resets + 1
    assert last_result(transport).step == 0
    transport.inject('light/command', command(0, mode=9))
    transport.advance(0.05)  # a bad command: the step happens with the light unchanged
    assert last_result(transport).step == 1 and 'mode' in last_result(transport).info
    stamps = [convert.to_ns(m.clock) for m in transport.messages('/clock')]
    assert np.all(np.diff(stamps) == 50_000_000)


def test_realtime_without_auto_reset_idles_after_the_episode() -> None:
    transport, node = make(SimConfig(episode_length=2), mode='realtime', rate_hz=10.0,
                           auto_reset=False)
    transport.advance(1.0)
    assert [m.step for m in transport.messages('step_result')] == [0, 1, 2]


def test_realtime_commands_are_recorded_when_received_even_while_the_chamber_idles() -> None:
    recorder = FakeRecorder()
    transport, node = make(SimConfig(episode_length=2), recorder=recorder, mode='realtime',
                           rate_hz=10.0, auto_reset=False)
    transport.advance(1.0)  # the episode is over; ticks publish nothing more
    calls = recorder.calls
    sent = [transport.inject('light/command', command(0, action=a)) for a in (1, 2)]
    assert recorder.calls == calls + 2 and [b[0][1] for b in recorder.batches[-2:]] == sent
    transport.advance(1.0)
    assert recorder.calls == calls + 2


def test_propose_rejects_invalid_changes_and_applies_valid_ones_at_reset() -> None:
    transport, node = make()
    error = node.propose({'light_width': 2.0})
    assert error and 'light_width' in error and '2.0' in error
    assert node.propose({'episode_length': 7}) is None and node.cfg.episode_length == 50
    transport.inject('reset', reset(1))
    assert node.cfg.episode_length == 7


def test_a_new_rate_moves_the_realtime_timer_and_sim_time_at_once() -> None:
    transport, node = make(SimConfig(episode_length=100), mode='realtime', rate_hz=10.0)
    transport.advance(1.0)
    assert len(transport.messages('step_result')) == 11  # the reset and 10 steps
    assert node.propose({'rate_hz': 40.0}) is None and node.params.rate_hz == 40.0
    transport.advance(1.0)
    results = transport.messages('step_result')
    assert len(results) == 11 + 40
    stamps = [convert.to_ns(m.header.stamp) for m in results[-41:]]
    assert set(np.diff(stamps)) == {25_000_000}


class FakeRecorder:
    def __init__(self) -> None:
        self.channels: list[tuple[str, str, object]] = []
        self.writes: list[tuple[int, bytes, int, int]] = []
        self.calls = 0
        self.batches: list[list[tuple[int, bytes, int, int]]] = []
        self.metadata: list[tuple[str, dict]] = []
        self.closed = 0
        self.error: str | None = None

    def add_channel(self, topic: str, typename: str, qos: object) -> int:
        self.channels.append((topic, typename, qos))
        return len(self.channels) - 1

    def write_many(self, messages: list[tuple[int, bytes, int, int]]) -> None:
        self.calls += 1
        self.writes += messages
        self.batches.append(list(messages))

    def add_metadata(self, name: str, data: dict) -> None:
        assert all(isinstance(v, str) for v in data.values())
        self.metadata.append((name, data))

    def close(self) -> None:
        self.closed += 1


def test_recorder_gets_every_message_exact_bytes() -> None:
    recorder = FakeRecorder()
    transport, node = make(recorder=recorder)
    sent = [transport.inject('light/command', command(i, action=i % 5)) for i in (1, 2)]
    sent.append(transport.inject('reset', reset(4)))
    topics = [c[0] for c in recorder.channels]
    assert sorted(topics) == sorted(transport.resolve(t) for _, t, _, _ in (*OUTPUTS, *INPUTS))
    recorded: dict[str, list[bytes]] = {t: [] for t in topics}
    for channel, cdr, log_ns, pub_ns in recorder.writes:
        recorded[topics[channel]].append(cdr)
        assert log_ns == pub_ns
    for name, published in transport.published.items():
        assert recorded[name] == [cdr for _, cdr in published], name
    assert recorded['/chamber1/light/command'] == sent[:2]
    assert recorded['/chamber1/reset'] == sent[2:]
    # One recorder call per callback (start, 2 commands, reset): what was received, then
    # what it caused; time order is handling order.
    assert recorder.calls == 4
    assert [batch[0][1] for batch in recorder.batches[1:]] == sent
    times = [log_ns for _, _, log_ns, _ in recorder.writes]
    assert times == sorted(times) and times[0] == node.params.period_ns
    assert [m[0] for m in recorder.metadata] == ['growspace']  # once, at start
    meta = recorder.metadata[0][1]
    assert meta['seed'] == str(SEED) and SimConfig.from_dict(json.loads(meta['config'])) == \
        SimConfig()
    assert (meta['namespace'], meta['mode'], meta['frame_id']) == ('/chamber1', 'lockstep',
                                                                   'chamber')
    assert {'chamber_width_m', 'chamber_height_m', 'frame_convention', 'version'} <= set(meta)
    node.close()
    node.close()
    assert recorder.closed == 1


def test_a_failing_recorder_does_not_stop_the_node() -> None:
    recorder = FakeRecorder()
    recorder.write_many = lambda *a: (_ for _ in ()).throw(OSError('disk full'))
    transport, node = make(recorder=recorder)
    transport.inject('light/command', command(1, action=1))
    assert last_result(transport).step == 1
    assert any('disk full' in w for w in transport.warnings)
    assert node.recording_error is None  # a passing failure: the node keeps recording


def test_a_stopped_recorder_is_reported_once_and_the_chamber_goes_on() -> None:
    recorder = FakeRecorder()
    transport, node = make(recorder=recorder)

    def fail(messages: list) -> None:
        recorder.calls += 1
        recorder.error = 'Cannot write recording x.mcap: No space left on device'
        raise RuntimeError(recorder.error)
    recorder.write_many = fail
    calls = recorder.calls
    for step_id in range(1, 21):
        transport.time_s += 10  # past any throttle: "once" is not the throttle
        transport.inject('light/command', command(step_id, action=1))
    assert last_result(transport).step == 20
    assert recorder.calls == calls + 1  # no more writes after it stopped
    stopped = [w for w in transport.warnings if 'No space left on device' in w]
    assert len(stopped) == 1 and 'recording stopped' in stopped[0]
    assert node.recording_error and 'No space' in node.recording_error


def test_malformed_bytes_never_reach_the_node() -> None:
    transport, node = make()
    transport.inject_raw('light/command', b'\x00\x01\x00\x00\x01')
    transport.inject_raw('reset', b'garbage')
    assert len(transport.messages('step_result')) == 1
    assert any('malformed' in w for w in transport.warnings)
    transport.inject('light/command', command(1, action=1))
    assert last_result(transport).step == 1


def test_unread_outputs_are_skipped_unless_recorded() -> None:
    transport, node = make()
    transport.unread = {'/chamber1/plant/state', '/clock'}
    transport.clear()
    transport.inject('light/command', command(1, action=1))
    assert not transport.messages('plant/state') and not transport.messages('/clock')
    assert transport.messages('camera/image_raw') and transport.messages('step_result')
    recorder = FakeRecorder()
    transport, node = make(recorder=recorder)
    transport.unread = {'/chamber1/plant/state'}
    transport.inject('light/command', command(1, action=1))
    assert len(transport.messages('plant/state')) == 2  # the recorder wants it
