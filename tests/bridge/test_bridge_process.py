"""Bridged envs that start their own nodes: dead and stalled nodes, cleanup, vector envs."""

from __future__ import annotations

from collections.abc import Iterator
import functools
import json
import os
import pickle
import signal
import subprocess
import sys
import threading
import time

import gymnasium as gym
import numpy as np
import pytest

from bridge_helpers import assert_same_transition, loopback_domain
import growspace_gym_bridge  # noqa: F401 - registers the GrowSpaceROS ids
from conftest import child_env, next_domain
from growspace_gym_bridge import BridgeTimeout, CommandRejected, NodeDied
from growspace_gym_bridge.errors import BridgeError
from growspace_gym_bridge.envs import GrowSpaceBridgeEnv
from growspace_sim.envs.env import GrowSpaceEnv
from growspace_sim.node.main import CLOSE_TIMEOUT_S

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

BRIDGED = 'GrowSpaceROS/Control-Easy-v0'
LOCAL = 'GrowSpace/Control-Easy-v0'


@pytest.fixture(scope='module', autouse=True)
def domain() -> Iterator[int]:
    yield from loopback_domain()


@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
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


@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
def test_stalled_node_times_out_and_its_late_reply_is_ignored() -> None:
    env = GrowSpaceBridgeEnv('control', 'easy', timeout_s=60.0)
    local = GrowSpaceEnv('control', 'easy')
    try:
        env.reset(seed=3)
        local.reset(seed=3)
        os.kill(env.node.pid, signal.SIGSTOP)
        env.timeout_s = 0.5  # short for the stalled step only: the others wait as in training
        try:
            with pytest.raises(BridgeTimeout, match=rf'{env.namespace}/step_result: no reply '
                               r'to light/command for step_id 1 .* timeout of 0.5 s') as caught:
                env.step(1)
            assert isinstance(caught.value, TimeoutError) and caught.value.step_id == 1
        finally:
            env.timeout_s = 60.0
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


def test_the_bridge_gives_a_closing_node_its_whole_bound_before_sigkill() -> None:
    from growspace_gym_bridge.process import STOP_TIMEOUT_S

    assert STOP_TIMEOUT_S > CLOSE_TIMEOUT_S  # its recording finished, or its own watchdog


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
    vec = (gym.make_vec(BRIDGED, num_envs=2, vectorization_mode='sync') if mode == 'sync'
           else _async_bridged())
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


# --- errors cross process boundaries; nodes never outlive their env (issue 24, item 1) -------

ERRORS = [NodeDied('/gs_a', -9, ['last line', 'another'], '/gs_a/step_result (step_id 2)'),
          NodeDied('/gs_b', None), BridgeTimeout('/gs_a/step_result', 0.5, 3, 7, 'no reply'),
          CommandRejected('/gs_a/light/command: step_id 4 refused: error: x = nan ...'),
          BridgeError('sim node /gs_a runs in realtime mode')]
CLOSE_BOUND_S = 25.0  # close() of a vector env with one dead or stalled node [s]: the
# bridge's STOP_TIMEOUT_S (12 s) and a margin for a loaded machine
# A node or worker whose owner died is gone by then [s]: a node's own closing is bounded by
# CLOSE_TIMEOUT_S, and noticing the death takes a parent poll or two.
GONE_WITHIN_S = CLOSE_TIMEOUT_S + 5.0


@pytest.mark.parametrize('error', ERRORS, ids=lambda e: type(e).__name__)
def test_every_bridge_error_survives_pickle_with_its_text_and_fields(error) -> None:
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is type(error) and str(back) == str(error)
    assert back.__dict__ == error.__dict__
    # Gymnasium's AsyncVectorEnv raises type(error)(error) in the parent.
    again = type(back)(back)
    assert type(again) is type(error) and str(again) == str(error)
    assert again.__dict__ == error.__dict__


def running(pid: int) -> bool:
    """Whether a process exists and is not a zombie (a dead child nobody reaped yet)."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            return f.read().rsplit(')', 1)[1].split()[0] not in 'ZX'
    except FileNotFoundError:
        return False


def wait_gone(pids: list[int], within_s: float = GONE_WITHIN_S) -> list[int]:
    """The pids still running after ``within_s``."""
    deadline = time.monotonic() + within_s
    while any(running(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    return [p for p in pids if running(p)]


def _async_bridged(**kwargs) -> gym.vector.AsyncVectorEnv:
    """Two bridged envs in spawned workers (a forked copy of a process that holds a DDS
    participant hangs), each with its chamber in a ROS domain of its own: the workers close
    together, and a participant torn down while it handles another's departure can hang for
    good (README, "Failure modes": eProsima/Fast-DDS#6513; seen twice, once in CI)."""
    # 'module:id' makes a spawned worker import the module that registers the id.
    makes = [functools.partial(gym.make, f'growspace_gym_bridge:{BRIDGED}',
                               domain_id=next_domain(), **kwargs) for _ in range(2)]
    return gym.vector.AsyncVectorEnv(makes, context='spawn')


@pytest.mark.parametrize('fault', ['killed', 'stalled'])  # in the workers' own domains
def test_async_vector_env_hands_the_parent_the_workers_error(fault: str) -> None:
    vec = _async_bridged(timeout_s=60.0)
    nodes, namespaces = list(vec.get_attr('node_pid')), vec.get_attr('namespace')
    workers = [p.pid for p in vec.processes]
    expected = NodeDied if fault == 'killed' else BridgeTimeout
    try:
        vec.reset(seed=[1, 2])
        # Short for the stalled worker's step only (a killed node is noticed without one);
        # the other worker's answer may be slow on a loaded machine.
        vec.set_attr('timeout_s', [1.0 if fault == 'stalled' else 60.0, 60.0])
        os.kill(nodes[0], signal.SIGKILL if fault == 'killed' else signal.SIGSTOP)
        with pytest.raises(expected) as caught:
            vec.step(np.array([0, 1]))
        assert namespaces[0] in str(caught.value) and namespaces[1] not in str(caught.value)
        if fault == 'killed':
            assert caught.value.returncode == -signal.SIGKILL
            assert 'exited with code -9 while the bridge waited for' in str(caught.value)
        else:
            assert caught.value.step_id == 1 and caught.value.timeout_s == 1.0
            assert 'no reply to light/command for step_id 1' in str(caught.value)
    finally:
        start = time.monotonic()
        vec.close()
        closing = time.monotonic() - start
    assert closing < CLOSE_BOUND_S
    assert wait_gone(nodes + workers) == []


def test_a_node_lives_as_long_as_its_process_not_the_thread_that_made_it() -> None:
    made = []

    def make() -> None:
        made.append(GrowSpaceBridgeEnv('control', 'easy'))
        made[0].reset(seed=1)  # the node is up before the thread ends

    thread = threading.Thread(target=make)
    thread.start()
    thread.join()
    env = made[0]
    try:
        # A deliberate negative check: the parent-death signal (thread-scoped on Linux) would
        # come at the thread's exit, which has no event to wait for when it does not come.
        time.sleep(0.5)
        assert env.step(0)[4]['step'] == 1 and env.node.poll() is None
    finally:
        env.close()


TRAINER = f"""
import functools, json, sys, time
import gymnasium as gym
import growspace_gym_bridge
if __name__ == '__main__':
    makes = [functools.partial(gym.make, 'growspace_gym_bridge:{BRIDGED}', domain_id=int(d))
             for d in sys.argv[2:4]]  # a domain each, as _async_bridged
    vec = gym.vector.AsyncVectorEnv(makes, context='spawn')
    vec.reset(seed=[1, 2])
    pids = list(vec.get_attr('node_pid')) + [p.pid for p in vec.processes]
    print(json.dumps(pids), flush=True)
    if sys.argv[1] == 'trainer':
        import os, signal
        os.kill(pids[0], signal.SIGSTOP)
    time.sleep(60)
"""


@pytest.mark.parametrize('victim', ['trainer', 'worker'])
def test_no_node_outlives_a_killed_trainer_or_worker(victim: str) -> None:
    # trainer: SIGKILL the vector env's process while one node is stalled (SIGSTOP); worker:
    # SIGKILL the worker process that started the first node.
    domains = [str(next_domain()) for _ in range(2)]
    trainer = subprocess.Popen([sys.executable, '-c', TRAINER, victim, *domains],
                               stdout=subprocess.PIPE, text=True, env=child_env())
    pids: list[int] = []
    try:
        pids = json.loads(trainer.stdout.readline())
        os.kill(trainer.pid if victim == 'trainer' else pids[2], signal.SIGKILL)
        assert wait_gone(pids if victim == 'trainer' else pids[:1]) == []
    finally:
        trainer.kill()
        trainer.wait()
        for pid in pids:
            if running(pid):
                os.kill(pid, signal.SIGCONT)
                os.kill(pid, signal.SIGKILL)
