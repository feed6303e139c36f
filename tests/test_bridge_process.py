"""Bridged envs that start their own nodes: dead and stalled nodes, cleanup, vector envs."""

from __future__ import annotations

from collections.abc import Iterator
import os
import signal
import time

import gymnasium as gym
import numpy as np
import pytest

from bridge_helpers import assert_same_transition, loopback_domain
import growspace_gym_bridge  # noqa: F401 - registers the GrowSpaceROS ids
from growspace_gym_bridge import BridgeTimeout, NodeDied
from growspace_gym_bridge.envs import GrowSpaceBridgeEnv
from growspace_sim.envs.env import GrowSpaceEnv

BRIDGED = 'GrowSpaceROS/Control-Easy-v0'
LOCAL = 'GrowSpace/Control-Easy-v0'


@pytest.fixture(scope='module', autouse=True)
def domain() -> Iterator[int]:
    yield from loopback_domain()


def test_killed_node_raises_node_died_with_its_exit_code() -> None:
    env = GrowSpaceBridgeEnv('control', 'easy', timeout_s=30.0)
    try:
        env.reset(seed=1)
        env.step(0)
        os.kill(env.node.pid, signal.SIGKILL)
        start = time.monotonic()
        with pytest.raises(NodeDied) as caught:
            env.step(1)
        assert time.monotonic() - start < 5.0  # noticed at once, not after the 30 s timeout
        assert caught.value.returncode == -signal.SIGKILL
        assert env.namespace in str(caught.value) and 'step_id 2' in str(caught.value)
    finally:
        env.close()
    assert env.node.poll() == -signal.SIGKILL  # reaped: no zombie left


def test_node_that_fails_to_start_reports_its_exit_code_and_stderr() -> None:
    env = GrowSpaceBridgeEnv('control', 'easy', node_params={'record_path': '/proc/nope.mcap'})
    try:
        with pytest.raises(NodeDied, match=r'(?s)exited with code [12] .*/proc/nope.mcap'):
            env.reset(seed=1)
    finally:
        env.close()


def test_stalled_node_times_out_and_its_late_reply_is_ignored() -> None:
    env = GrowSpaceBridgeEnv('control', 'easy', timeout_s=0.5)
    local = GrowSpaceEnv('control', 'easy')
    try:
        env.reset(seed=3)
        local.reset(seed=3)
        os.kill(env.node.pid, signal.SIGSTOP)
        try:
            with pytest.raises(BridgeTimeout, match=rf'{env.namespace}/step_result: no reply '
                               r'to light/command for step_id 1 .* timeout of 0.5 s') as caught:
                env.step(1)
            assert isinstance(caught.value, TimeoutError) and caught.value.step_id == 1
        finally:
            os.kill(env.node.pid, signal.SIGCONT)
        local.step(1)  # the node still runs step 1 when it wakes up
        bridged = env.step(2)
        assert bridged[4]['step'] == 2 and env.link.stale >= 1  # step 1's reply was dropped
        assert_same_transition(bridged, local.step(2), 'after the late reply')
    finally:
        env.close()


def test_attaching_to_no_node_times_out_naming_the_topic() -> None:
    with pytest.raises(BridgeTimeout, match=r'/nobody_home/.*within the timeout of 1 s'):
        GrowSpaceBridgeEnv(namespace='/nobody_home', connect_timeout_s=1.0)


def test_invalid_parameter_is_refused_before_any_node_starts() -> None:
    with pytest.raises(ValueError, match='light_width'):
        GrowSpaceBridgeEnv('control', 'easy', light_width=-1.0)


def test_close_stops_the_node_cleanly_and_is_idempotent() -> None:
    env = gym.make(BRIDGED)
    env.reset(seed=0)
    node = env.unwrapped.node
    env.close()
    env.close()
    assert node.poll() == 0  # SIGTERM: the node shut down on its own


def _rollout(vec: gym.vector.VectorEnv, steps: int) -> list[tuple]:
    out = [vec.reset(seed=[11, 12])]
    for k in range(steps):
        out.append(vec.step(np.array([k % 5, (k + 2) % 5])))
    return out


@pytest.mark.parametrize('mode', ['sync', 'async'])
def test_vector_env_of_two_bridged_envs(mode: str) -> None:
    # Spawned workers: a forked copy of a process that holds a DDS participant hangs.
    kwargs = {'context': 'spawn'} if mode == 'async' else {}
    vec = gym.make_vec(BRIDGED, num_envs=2, vectorization_mode=mode, vector_kwargs=kwargs)
    local = gym.make_vec(LOCAL, num_envs=2, vectorization_mode='sync')
    try:
        namespaces = vec.get_attr('namespace')
        assert len(set(namespaces)) == 2  # one node and namespace per sub-env
        bridged, in_process = _rollout(vec, 12), _rollout(local, 12)
        for i, (b, ref) in enumerate(zip(bridged, in_process)):
            assert_same_transition(b, ref, f'{mode} vector call {i}')
        if mode == 'async':  # both workers wait for their nodes at the same time
            vec.step_async(np.array([0, 1]))
            assert_same_transition(vec.step_wait(), local.step(np.array([0, 1])), 'async')
        assert len(set(vec.get_attr('node_pid'))) == 2
    finally:
        vec.close()
        local.close()
