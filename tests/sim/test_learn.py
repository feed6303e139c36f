"""Learned baselines (growspace_sim.learn): smoke training per algorithm, checkpoints, eval table.

Needs the learn extra (requirements-learn.txt); without torch / Stable-Baselines3 the module is
skipped. Runs are a few hundred steps on one torch thread; the long run is marked ``slow``.
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

torch = pytest.importorskip('torch')
pytest.importorskip('stable_baselines3')
pytest.importorskip('pandas')

import gymnasium as gym  # noqa: E402

import growspace_sim  # noqa: E402, F401
from growspace_sim.learn import evaluate_policies, train  # noqa: E402
from growspace_sim.learn.networks import GrowSpaceCNN  # noqa: E402

ENV = 'GrowSpace/Control-Easy-v0'
# Small enough for a few hundred steps; each algorithm still runs several updates.
SMOKE_HP = {
    'ppo': {'n_steps': 64, 'batch_size': 32, 'n_epochs': 2},
    'a2c': {},
    'dqn': {'buffer_size': 500, 'learning_starts': 100, 'target_update_interval': 100},
    'rainbow': {'buffer_size': 500, 'learning_starts': 100, 'target_update_interval': 100},
}
LOSS_KEYS = {'ppo': ['train/loss'], 'a2c': ['train/policy_loss', 'train/value_loss'],
             'dqn': ['train/loss'], 'rainbow': ['train/loss']}


@pytest.fixture(autouse=True)
def one_thread():
    torch.set_num_threads(1)  # other processes share the cores: more threads is ~100x slower


def _smoke_run(algo, out, steps=300):
    return train.train(algo, ENV, steps, seed=0, out=out, n_envs=1, device='cpu',
                       hp=SMOKE_HP[algo], checkpoint_every=100, progress_bar=False,
                       log_interval=1)


@pytest.mark.parametrize('algo', sorted(train.ALGOS))
def test_smoke_training_has_finite_loss_and_checkpoints_load_and_act(algo, tmp_path):
    run = _smoke_run(algo, tmp_path / algo)

    with open(run / 'progress.csv', newline='') as f:
        rows = list(csv.DictReader(f))
    for key in LOSS_KEYS[algo]:
        losses = [float(r[key]) for r in rows if r.get(key)]
        assert losses, f'{algo}: no {key} logged'
        assert all(math.isfinite(v) for v in losses), f'{algo}: {key} = {losses}'
    with open(run / 'episodes.csv', newline='') as f:
        episodes = list(csv.DictReader(f))
    assert len(episodes) >= 5 and all(int(e['length']) == 50 for e in episodes)
    info = json.loads((run / 'run.json').read_text())
    assert info['algo'] == algo and info['steps'] >= 300

    checkpoints = sorted((run / 'checkpoints').glob(f'{algo}_*_steps.zip'))
    assert checkpoints, 'no checkpoint written'
    env = gym.make(ENV)
    observation, _ = env.reset(seed=1)
    for path in (checkpoints[-1], run):
        model = train.load_model(path)
        for deterministic in (True, False):
            action, _ = model.predict(observation, deterministic=deterministic)
            assert env.action_space.contains(int(action))
    env.close()


def test_ppo_defaults_are_the_papers():
    assert train.DEFAULTS['ppo'] == dict(
        learning_rate=2.5e-4, n_steps=2500, batch_size=32, n_epochs=4, gamma=0.99,
        gae_lambda=0.95, clip_range=0.1, ent_coef=0.01, max_grad_norm=0.5)


@pytest.mark.parametrize('shape', [(3, 84, 84), (3, 28, 28)])
def test_cnn_encoder_handles_both_observation_sizes(shape):
    space = gym.spaces.Box(0, 255, shape, np.uint8)
    encoder = GrowSpaceCNN(space, features_dim=64)
    assert encoder(torch.zeros(2, *shape)).shape == (2, 64)


def test_rainbow_projection_keeps_probability_mass(tmp_path):
    run = _smoke_run('rainbow', tmp_path / 'rb', steps=200)
    model = train.load_model(run)
    probs = model.q_net.dist(torch.zeros(4, 3, 84, 84))
    assert probs.shape == (4, 5, 51)
    torch.testing.assert_close(probs.sum(dim=2), torch.ones(4, 5))


def test_hp_parsing_and_cli_errors():
    assert train.parse_hp(['n_steps=500', 'clip_range=0.2', 'policy=x']) == {
        'n_steps': 500, 'clip_range': 0.2, 'policy': 'x'}
    with pytest.raises(ValueError, match='key=value'):
        train.parse_hp(['n_steps'])
    with pytest.raises(SystemExit):
        train.main(['--env', 'GrowSpace/Nope-v0', '--steps', '10'])


def test_eval_table_on_a_tiny_budget_has_the_expected_columns(tmp_path):
    run = _smoke_run('ppo', tmp_path / 'ppo', steps=128)
    out = tmp_path / 'eval'
    assert evaluate_policies.main(['--run', str(run), '--episodes', '2', '--out', str(out)]) == 0

    with open(out / 'results.csv', newline='') as f:
        reader = csv.DictReader(f)
        rows = list(reader)
    assert tuple(reader.fieldnames) == evaluate_policies.COLUMNS == (
        'case', 'env', 'agent', 'runs', 'episodes', 'steps', 'mean', 'se')
    assert [r['agent'] for r in rows] == ['random', 'oracle', 'ppo']
    assert {r['case'] for r in rows} == {'control/easy'}
    assert all(int(r['episodes']) == 2 and math.isfinite(float(r['mean'])) for r in rows)
    assert (out / 'results.md').read_text().startswith('| case | agent |')
    for figure in ('rewards.png', 'training.png'):
        assert (out / figure).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    merged, _ = evaluate_policies.load_results(out)
    assert [r.agent for r in merged] == [r['agent'] for r in rows]


def test_training_through_the_ros_bridge(tmp_path):
    pytest.importorskip('growspace_gym_bridge')
    run = train.train('ppo', ENV, 100, seed=0, out=tmp_path / 'bridge', n_envs=1,
                      device='cpu', hp={'n_steps': 50, 'batch_size': 25, 'n_epochs': 1},
                      progress_bar=False, log_interval=1, bridge=True)
    info = json.loads((run / 'run.json').read_text())
    assert info['bridge'] is True and info['steps'] >= 100
    with open(run / 'progress.csv', newline='') as f:
        losses = [float(r['train/loss']) for r in csv.DictReader(f) if r.get('train/loss')]
    assert losses and all(math.isfinite(v) for v in losses)


@pytest.mark.parametrize('env_id', [ENV, 'GrowSpace/Shape-Hard-v0'])
def test_native_vec_env_gives_sb3_the_steps_dummy_vec_env_gives(env_id):
    from stable_baselines3.common.env_util import make_vec_env

    dummy = make_vec_env(env_id, n_envs=3, seed=7)
    native = train.make_env(env_id, 3, 7, vec='native')
    np.testing.assert_array_equal(native.reset(), dummy.reset())
    actions = np.random.default_rng(0).integers(0, native.action_space.n, (110, 3))
    ended = 0
    for step, action in enumerate(actions):  # two episode ends of 50 steps each
        obs, rewards, dones, infos = native.step(action)
        want_obs, want_rewards, want_dones, want_infos = dummy.step(action)
        np.testing.assert_array_equal(obs, want_obs, err_msg=f'step {step}')
        np.testing.assert_array_equal(rewards, want_rewards)
        assert rewards.dtype == want_rewards.dtype and dones.dtype == want_dones.dtype
        np.testing.assert_array_equal(dones, want_dones)
        for info, want in zip(infos, want_infos):
            assert set(info) == set(want) - {'tips'}
            for key in set(info) - {'episode'}:
                np.testing.assert_equal(info[key], want[key], err_msg=f'{key} at step {step}')
            if 'episode' in want:
                assert info['episode']['l'] == want['episode']['l'] == 50
                # VecMonitor sums the float32 rewards, Monitor the float64 ones.
                assert info['episode']['r'] == pytest.approx(want['episode']['r'], rel=1e-5)
                ended += 1
    assert ended == 6
    assert native.get_attr('render_mode') == [None] * 3
    native.close()
    dummy.close()


def test_ppo_trains_on_the_native_vec_env_and_bad_choices_are_refused(tmp_path):
    run = train.train('ppo', ENV, 256, seed=0, out=tmp_path / 'native', n_envs=4, device='cpu',
                      hp=SMOKE_HP['ppo'], progress_bar=False, log_interval=1, vec='native')
    with open(run / 'episodes.csv', newline='') as f:
        episodes = list(csv.DictReader(f))
    assert len(episodes) == 4 and all(int(e['length']) == 50 for e in episodes)
    assert json.loads((run / 'run.json').read_text())['vec'] == 'native'
    with pytest.raises(ValueError, match='bridge'):
        train.make_env(ENV, 2, 0, vec='native', bridge=True)
    with pytest.raises(ValueError, match="vec must be one of .* got 'fast'"):
        train.make_env(ENV, 2, 0, vec='fast')
    with pytest.raises(SystemExit):
        train.main(['--vec', 'native', '--bridge', '--steps', '10'])


def test_device_rollout_buffer_trains_exactly_as_sb3s_buffer():
    """The same minibatches in the same order: the weights after an update are identical."""
    params = {}
    for kind in train.BUFFER_KINDS:
        env = train.make_env(ENV, 2, 0, vec='native')
        model = train.build_model('ppo', env, 0, 'cpu', SMOKE_HP['ppo'], rollout_buffer=kind)
        model.learn(total_timesteps=256)  # two updates of 2 x 64 steps
        params[kind] = [p.detach().clone() for p in model.policy.parameters()]
        env.close()
    assert len(params['sb3']) == len(params['device'])
    for sb3, device in zip(params['sb3'], params['device']):
        assert torch.equal(sb3, device)
    with pytest.raises(ValueError, match="rollout_buffer='device' is for ppo and a2c, not 'dqn'"):
        train.build_model('dqn', train.make_env(ENV, 1, 0), 0, 'cpu', rollout_buffer='device')
    with pytest.raises(ValueError, match="rollout_buffer must be one of .* got 'gpu'"):
        train.build_model('ppo', train.make_env(ENV, 1, 0), 0, 'cpu', rollout_buffer='gpu')
    with pytest.raises(SystemExit):
        train.main(['--algo', 'dqn', '--rollout-buffer', 'device', '--steps', '10'])


def test_resume_continues_a_run_and_its_curriculum_up_to_the_steps(tmp_path):
    env_id = 'GrowSpace/Shape-Curriculum-v0'
    kwargs = dict(seed=0, out=tmp_path / 'run', n_envs=2, device='cpu', hp=SMOKE_HP['ppo'],
                  env_kwargs={'episodes_per_stage': 1}, vec='native', progress_bar=False,
                  log_interval=1, rollout_buffer='device', resume=True)
    run = train.train('ppo', env_id, 128, **kwargs)  # nothing to resume: a fresh run
    first = json.loads((run / 'run.json').read_text())
    assert first['steps'] == 128 and len(first['legs']) == 1
    assert first['curriculum_clock'] == [2, 2]  # 64 steps per chamber: episodes 1 and 2 begun

    train.train('ppo', env_id, 256, **kwargs)
    second = json.loads((run / 'run.json').read_text())
    assert second['steps'] == 256
    assert [(leg['steps_from'], leg['steps_to']) for leg in second['legs']] == [(0, 128),
                                                                              (128, 256)]
    assert second['curriculum_clock'] == [4, 4]  # the clock went on from 2, not from 0
    assert second['wall_s'] >= first['wall_s']
    with open(run / 'episodes.csv', newline='') as f:
        episodes = list(csv.DictReader(f))
    timesteps = [int(e['timestep']) for e in episodes]
    assert len(episodes) == 4 and timesteps == sorted(timesteps) and timesteps[-1] > 128
    assert (run / 'progress_until_128.csv').exists() and (run / 'progress.csv').exists()

    before = (run / 'run.json').read_text()
    train.train('ppo', env_id, 256, **kwargs)  # reached: nothing to do
    assert (run / 'run.json').read_text() == before
    with pytest.raises(ValueError, match='trained on 2 envs, not 4'):
        train.train('ppo', env_id, 512, **{**kwargs, 'n_envs': 4})


@pytest.mark.learning
def test_ppo_learns_control_hard(tmp_path):
    """About 3 minutes on one core: PPO (case-study settings) beats random on control hard."""
    env_id = 'GrowSpace/Control-Hard-v0'
    run = train.train('ppo', env_id, 30_000, seed=0, out=tmp_path / 'ppo', n_envs=8,
                      device='cpu', hp={'n_steps': 256, 'batch_size': 64}, progress_bar=False)
    results = evaluate_policies.evaluate_env(env_id, [str(run)], episodes=20)
    rows = {r.agent: r for r in evaluate_policies.rows_for(env_id, results)}
    assert rows['ppo'].mean - rows['ppo'].se > rows['random'].mean + rows['random'].se
