"""The bridged env against one shared lockstep node: Gymnasium checks and exact equivalence."""

from __future__ import annotations

from collections.abc import Iterator
import pickle
import secrets

import gymnasium as gym
from gymnasium.utils.env_checker import check_env
import numpy as np
import pytest

from bridge_helpers import assert_same_transition, loopback_domain
import growspace_gym_bridge  # noqa: F401 - registers the GrowSpaceROS ids
from growspace_gym_bridge.envs import GrowSpaceBridgeEnv
from growspace_gym_bridge.process import NodeProcess
from growspace_sim.envs.env import GrowSpaceEnv

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

NAMESPACE = f'/gs_bridge_test_{secrets.token_hex(3)}'
EPISODE = 50


@pytest.fixture(scope='module', autouse=True)
def node() -> Iterator[NodeProcess]:
    """One lockstep node for the whole module; each test's env switches its challenge."""
    for _ in loopback_domain():
        process = NodeProcess(NAMESPACE, {'mode': 'lockstep', 'seed': 1})
        try:
            yield process
        finally:
            assert process.stop() == 0, process.stderr_tail()


def attach(challenge: str = 'control', setting: str = 'easy', **kwargs) -> GrowSpaceBridgeEnv:
    return GrowSpaceBridgeEnv(challenge, setting, namespace=NAMESPACE, **kwargs)


def test_gymnasium_check_env_on_a_bridged_id() -> None:
    env = gym.make('GrowSpaceROS/Control-Easy-v0', namespace=NAMESPACE)
    try:
        check_env(env.unwrapped)
    finally:
        env.close()


def test_spaces_equal_the_in_process_env() -> None:
    for challenge, continuous in (('control', False), ('shape', False), ('fairness', True),
                                  ('shape', True)):
        env = attach(challenge, continuous=continuous)
        local = GrowSpaceEnv(challenge, continuous=continuous)
        assert env.action_space == local.action_space, challenge
        assert env.observation_space == local.observation_space, challenge
        assert env.cfg == local.cfg
        env.close()


@pytest.mark.parametrize('challenge,setting,continuous', [
    ('control', 'easy', False), ('find_plant', 'easy', False), ('fairness', 'easy', False),
    ('shape', 'easy', False), ('control', 'hard', False), ('fairness', 'hard', True)])
def test_full_episode_is_bit_identical_to_in_process(challenge: str, setting: str,
                                                     continuous: bool) -> None:
    env = attach(challenge, setting, continuous=continuous)
    local = GrowSpaceEnv(challenge, setting, continuous=continuous)
    try:
        for seed in (7, None):  # a seeded episode, then one continuing the random stream
            first = env.reset(seed=seed), local.reset(seed=seed)
            assert_same_transition(first[0], first[1], f'{challenge} reset')
            env.action_space.seed(seed or 0)
            for step in range(1, EPISODE + 1):
                action = env.action_space.sample()
                bridged, in_process = env.step(action), local.step(action)
                assert_same_transition(bridged, in_process, f'{challenge} step {step}')
            assert bridged[3] and bridged[4]['step'] == EPISODE
    finally:
        env.close()


def test_reset_twice_in_a_row_then_step() -> None:
    env = attach()
    local = GrowSpaceEnv()
    try:
        env.reset(seed=5)
        obs, info = env.reset(seed=5)
        local_obs, local_info = local.reset(seed=5)
        assert_same_transition((obs, info), (local_obs, local_info), 'second reset')
        assert_same_transition(env.step(1), local.step(1), 'step after two resets')
        with pytest.raises(gym.error.ResetNeeded):
            attach().step(0)  # a fresh env has no episode yet
    finally:
        env.close()


def test_stepping_a_finished_episode_asks_for_a_reset() -> None:
    env = attach(episode_length=EPISODE)
    try:
        env.reset(seed=2)
        for _ in range(EPISODE):
            *_, truncated, _ = env.step(2)
        assert truncated
        with pytest.raises(gym.error.ResetNeeded, match='episode is over'):
            env.step(2)
        env.reset(seed=2)
        assert env.step(2)[4]['step'] == 1
    finally:
        env.close()


def test_rejected_command_is_a_value_error_naming_the_topic() -> None:
    env = attach()
    try:
        env.reset(seed=1)
        with pytest.raises(ValueError, match=r'light/command: step_id 1 refused: error: action'):
            env.step(9)
        assert env.step(0)[4]['step'] == 1  # the chamber did not move on the bad one
    finally:
        env.close()


def test_features_observation_and_render() -> None:
    env = attach(observation='features', render_mode='rgb_array')
    local = GrowSpaceEnv(observation='features', render_mode='rgb_array')
    try:
        assert np.array_equal(env.reset(seed=3)[0], local.reset(seed=3)[0])
        assert np.array_equal(env.step(1)[0], local.step(1)[0])
        assert np.array_equal(env.render(), local.render())
    finally:
        env.close()


def test_pickles_by_constructor_arguments() -> None:
    env = attach('find_plant', timeout_s=3.0)
    clone = pickle.loads(pickle.dumps(env))
    try:
        assert (clone.namespace, clone.cfg, clone.timeout_s) == (NAMESPACE, env.cfg, 3.0)
        assert np.array_equal(clone.reset(seed=4)[0], GrowSpaceEnv('find_plant').reset(seed=4)[0])
    finally:
        clone.close()
        env.close()


def test_stable_baselines3_env_checker() -> None:
    env_checker = pytest.importorskip('stable_baselines3.common.env_checker')
    env = attach()
    try:
        env_checker.check_env(env)
    finally:
        env.close()
