"""The sim_node in a subprocess over loopback Cyclone DDS, driven by a plain ros.dds client."""

from __future__ import annotations

import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import time
from typing import Any, Callable, Iterator

import pytest

from growspace_sim.ros import dds, qos, types

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config' / 'cyclonedds.xml'
NAMESPACE = '/gs_node_test'
COMMANDS = qos.QosProfile(depth=100)
OBSERVATIONS = qos.QosProfile(depth=10)
TIMEOUT_S = 20.0


@pytest.fixture(scope='module', autouse=True)
def loopback_env() -> Iterator[None]:
    """Loopback-only Cyclone config and a random domain, for us and the node."""
    saved = {k: os.environ.get(k) for k in ('CYCLONEDDS_URI', 'ROS_DOMAIN_ID', 'PYTHONPATH',
                                            'GROWSPACE_TRANSPORT')}
    os.environ['CYCLONEDDS_URI'] = CONFIG.as_uri()
    os.environ['ROS_DOMAIN_ID'] = str(random.SystemRandom().randint(100, 200))
    os.environ['GROWSPACE_TRANSPORT'] = 'dds'
    os.environ['PYTHONPATH'] = os.pathsep.join(
        [str(ROOT / 'src' / 'growspace_sim')] + ([saved['PYTHONPATH']] if saved['PYTHONPATH']
                                                 else []))
    yield
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


class NodeProcess:
    """The node as a child process; always killed at the end."""

    def __init__(self, *ros_args: str, namespace: str = NAMESPACE) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, '-m', 'growspace_sim.node.main', '--ros-args', '-r',
             f'__ns:={namespace}', *ros_args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def stop(self, sig: int = signal.SIGTERM) -> tuple[int, str]:
        try:
            if self.proc.poll() is None:
                self.proc.send_signal(sig)
            _, err = self.proc.communicate(timeout=TIMEOUT_S)
            return self.proc.returncode, err
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()


class Client:
    """A lockstep client on ros.dds only."""

    def __init__(self, ctx: dds.DdsContext) -> None:
        self.command = ctx.create_publisher(types.LIGHT_COMMAND, 'light/command', COMMANDS)
        self.reset_pub = ctx.create_publisher(types.RESET_REQUEST, 'reset', COMMANDS)
        self.results = ctx.create_subscription(types.STEP_RESULT, 'step_result', OBSERVATIONS)
        self.images = ctx.create_subscription('sensor_msgs/msg/Image', 'camera/image_raw',
                                              OBSERVATIONS)
        self.seen: list[Any] = []

    def connect(self) -> None:
        assert self.command.wait_for_subscribers(1, TIMEOUT_S), 'node did not subscribe'
        assert self.reset_pub.wait_for_subscribers(1, TIMEOUT_S)
        assert self.results.wait_for_publishers(1, TIMEOUT_S), 'node did not publish'

    def wait_result(self, match: Callable[[Any], bool], timeout: float = 10.0) -> Any:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.results.wait(min(0.2, max(0.0, deadline - time.monotonic())))
            for _, msg in self.results.take():
                assert not isinstance(msg, types.CdrError), msg
                self.seen.append(msg)
                if match(msg):
                    return msg
        raise TimeoutError('no matching StepResult in time')

    def reset(self, reset_id: int, **fields: Any) -> Any:
        self.reset_pub.publish(types.new(types.RESET_REQUEST, reset_id=reset_id, **fields))
        return self.wait_result(lambda m: m.reset_id == reset_id and m.step_id == 0)

    def step(self, step_id: int, action: int) -> Any:
        self.command.publish(types.new(types.LIGHT_COMMAND, step_id=step_id, mode=2,
                                       action=action))
        return self.wait_result(lambda m: m.step_id == step_id)

    def drain(self, seconds: float) -> list[Any]:
        end = time.monotonic() + seconds
        out = []
        while time.monotonic() < end:
            self.results.wait(0.05)
            out += [m for _, m in self.results.take()]
        return out


def test_lockstep_reset_and_50_steps_each_answered_once() -> None:
    node = NodeProcess('-p', 'seed:=4')
    try:
        with dds.DdsContext('client', NAMESPACE) as ctx:
            client = Client(ctx)
            client.connect()
            first = client.reset(77, has_seed=True, seed=21)
            assert first.step == 0 and not first.info
            for step_id in range(1, 51):
                result = client.step(step_id, step_id % 5)
                assert result.step == step_id and result.info == ''
            assert result.truncated
            late = client.drain(0.3)
            answered = [m.step_id for m in client.seen + late if m.step_id]
            assert answered == list(range(1, 51))  # each exactly once, in order
            images = client.images.take(256)
            assert images and all(not isinstance(m, types.CdrError) for _, m in images)
    finally:
        code, err = node.stop()
    assert code == 0, err


def test_realtime_mode_steps_at_the_configured_rate() -> None:
    rate, seconds = 20.0, 1.5
    node = NodeProcess('-p', 'mode:=realtime', '-p', f'rate_hz:={rate}', '-p',
                       'episode_length:=1000')
    try:
        with dds.DdsContext('client', NAMESPACE) as ctx:
            client = Client(ctx)
            client.connect()
            client.drain(0.3)  # let the timer settle after discovery
            got = client.drain(seconds)
            steps = [m for m in got if m.step > 0]
            assert abs(len(steps) - rate * seconds) <= 0.25 * rate * seconds, len(steps)
            assert all(m.step_id == 0 for m in steps)
            assert [b.step - a.step for a, b in zip(steps, steps[1:])] == [1] * (len(steps) - 1)
    finally:
        code, err = node.stop(signal.SIGINT)
    assert code == 0, err


def test_sigterm_exits_cleanly_and_namespaces_isolate_chambers() -> None:
    a = NodeProcess('-p', 'seed:=1', namespace='/chamber_a')
    b = NodeProcess('-p', 'seed:=2', namespace='/chamber_b')
    try:
        with dds.DdsContext('client', '/chamber_b') as ctx:
            Client(ctx).connect()  # b is up (its signal handlers too) before it gets SIGTERM
        with dds.DdsContext('client', '/chamber_a') as ctx:
            client = Client(ctx)
            client.connect()
            client.reset(5)
            client.step(1, 1)
            assert client.command.matched_count() == 1  # only chamber_a's node
    finally:
        code_a, err_a = a.stop()
        code_b, err_b = b.stop()
    assert code_a == 0 and code_b == 0, err_a + err_b
    assert 'Traceback' not in err_a + err_b


@pytest.mark.parametrize(('args', 'words'), [
    (['-p', 'light_width:=7.5'], ['light_width', '7.5']),
    (['-p', 'mode:=turbo'], ['mode', 'turbo', 'realtime']),
    (['-p', 'episode_length:=0'], ['episode_length', '0']),
])
def test_invalid_startup_parameter_exits_2_naming_it(args: list[str], words: list[str]) -> None:
    node = NodeProcess(*args)
    try:
        code = node.proc.wait(timeout=TIMEOUT_S)
        err = node.proc.stderr.read()
    finally:
        node.stop()
    assert code == 2
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and all(w in lines[0] for w in words), err
