"""Fuzz: >= 10,000 random or malformed commands, then the node still resets and steps right."""

from __future__ import annotations

import math
import random

import numpy as np

import pytest

from growspace_sim.core.config import SimConfig
from growspace_sim.envs.env import GrowSpaceEnv
from growspace_sim.node.chamber_node import ChamberNode
from growspace_sim.node.fake import FakeTransport
from growspace_sim.node.params import NodeParams
from growspace_sim.node.rclpy_transport import RclpyTransport
from growspace_sim.ros import convert
from growspace_sim.ros import types
from growspace_sim.ros.interface import COMMAND_QOS
from growspace_msgs.msg import LightCommand
from ros_helpers import Client, NodeProcess

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

NAMESPACE = '/gs_fuzz'

FLOATS = [0.0, -0.0, 0.3, -1.0, 1.0, 1e308, -1e308, math.nan, math.inf, -math.inf, 5e-324, 84.0]
INTS = [0, 1, 2, 4, 5, 6, 7, -1, 2**31 - 1, -2**31]
STEP_IDS = [0, 1, 2, 3, 50, 2**63, 2**64 - 1]


def random_command(rng: random.Random) -> object:
    def number() -> float:
        return rng.choice(FLOATS) if rng.random() < 0.5 else rng.uniform(-2.0, 2.0)
    size = rng.choice([0, 1, 2, 3, 4, 100])
    with np.errstate(over='ignore'):  # 1e308 as float32 is inf, on purpose
        continuous = np.array([number() for _ in range(size)], np.float32)
    return types.new(
        types.LIGHT_COMMAND, step_id=rng.choice(STEP_IDS + [rng.randrange(2**64)]),
        mode=rng.randrange(256) if rng.random() < 0.2 else rng.randrange(4),
        x=number(), z=number(), width=number(), radius=number(),
        action=rng.choice(INTS), continuous=continuous,
        header=convert.header(rng.randrange(2**31) * 10**9, 'x' * rng.randrange(5)))


def garbage(rng: random.Random) -> bytes:
    body = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 160)))
    roll = rng.random()
    if roll < 0.4:
        return types.CDR_LE_HEADER + body
    if roll < 0.7:  # a real command cut short or with bytes flipped
        cdr = bytearray(types.serialize(random_command(rng), types.LIGHT_COMMAND))
        if rng.random() < 0.5:
            return bytes(cdr[:rng.randrange(len(cdr))])
        for _ in range(3):
            cdr[rng.randrange(len(cdr))] = rng.randrange(256)
        return bytes(cdr)
    return body


def assert_steps_like_the_env(transport: FakeTransport) -> None:
    transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=42, has_seed=True,
                                        seed=8, challenge='control', setting='easy'))
    env = GrowSpaceEnv()
    env.reset(seed=8)
    for step_id in range(1, 6):
        transport.inject('light/command', types.new(types.LIGHT_COMMAND, step_id=step_id,
                                                    mode=convert.MODE_DISCRETE, action=1))
        obs, reward, *_ = env.step(1)
        result = transport.messages('step_result')[-1]
        assert (result.step_id, result.step, result.reward, result.info) == (
            step_id, step_id, reward, '')
        assert np.array_equal(
            convert.image_from_msg(transport.messages('camera/image_raw')[-1]), obs)


def test_ten_thousand_random_and_malformed_commands_in_process() -> None:
    rng = random.Random(20240601)
    transport = FakeTransport()
    ChamberNode(transport, SimConfig(), NodeParams(seed=1))  # subscribes to the transport
    for i in range(10_000):
        roll = rng.random()
        if roll < 0.6:
            transport.inject('light/command', random_command(rng))
        elif roll < 0.95:
            transport.inject_raw('light/command', garbage(rng))
        elif roll < 0.98:
            transport.inject_raw('reset', garbage(rng))
        else:
            transport.inject('reset', types.new(
                types.RESET_REQUEST, reset_id=i, has_seed=rng.random() < 0.5,
                seed=rng.choice([0, 1, 2**63, 2**64 - 1]),
                challenge=rng.choice(['', 'control', 'shape', 'fairness', 'bogus']),
                setting=rng.choice(['', 'easy', 'hard', '??'])))
        if i % 1000 == 0:
            transport.clear()  # bounded memory
    assert not any('callback failed' in w for w in transport.warnings), transport.warnings
    for _, msgs in transport.published.items():
        for msg, _ in msgs:
            for field in ('reward', 'x', 'z', 'width', 'radius'):
                if hasattr(msg, field):
                    assert math.isfinite(getattr(msg, field)), (field, msg)
    transport.clear()
    assert_steps_like_the_env(transport)


def test_fuzz_over_ros_with_raw_garbage_then_lockstep_still_works() -> None:
    rng = random.Random(7)
    node = NodeProcess('-p', 'seed:=3', namespace=NAMESPACE)
    client = Client(NAMESPACE)
    fuzzer = RclpyTransport('fuzzer', NAMESPACE)
    try:
        client.connect()
        raw = {topic: fuzzer.raw_publisher(typename, topic, COMMAND_QOS)
               for topic, typename in (('light/command', types.LIGHT_COMMAND),
                                       ('reset', types.RESET_REQUEST))}
        assert client.spin_until(lambda: all(map(fuzzer.matched, raw)))
        with pytest.raises(ValueError, match=r'/light/command: an empty message cannot be'):
            raw['light/command'](b'')
        for i in range(1_200):
            topic = 'light/command' if rng.random() < 0.9 else 'reset'
            if rng.random() < 0.5:
                raw[topic](garbage(rng) or b'\x00')  # DDS sends no empty message (above)
            elif topic == 'light/command':
                raw[topic](types.serialize(random_command(rng), types.LIGHT_COMMAND))
            else:
                raw[topic](types.serialize(types.new(
                    types.RESET_REQUEST, reset_id=10**6 + i,
                    challenge=rng.choice(['', 'x', 'shape'])), types.RESET_REQUEST))
        # Every message of the flood reached the node (after an empty one, the fuzzer's writer
        # held back all it sent: a third of the flood, never acknowledged). Then a command of
        # our own: its answer shows the node has taken everything before it.
        assert fuzzer.flush(60.0), 'the node did not acknowledge all of the flood'
        fuzzer.close()
        client.command.publish(LightCommand(step_id=2**64 - 1, action=2))
        client.wait_result(lambda m: m.step_id == 2**64 - 1, timeout=60.0)
        assert node.proc.poll() is None, 'the node died'
        first = client.reset(4242, has_seed=True, seed=8, challenge='control', setting='easy')
        assert first.step == 0 and first.info == ''
        env = GrowSpaceEnv()
        env.reset(seed=8)
        for step_id in range(1, 6):
            result = client.step(step_id, 1)
            _, reward, *_ = env.step(1)
            assert (result.step, result.reward, result.info) == (step_id, reward, '')
    finally:
        fuzzer.close()
        client.close()
        code, err = node.stop()
    assert code == 0, err
    assert 'Traceback' not in err
