"""A challenge defined in this file alone runs end to end: env, in-process node, recording.

This is the proof that adding a challenge is one ``Task`` and one ``register`` call (issue 10):
nothing else in the package names it.
"""

from __future__ import annotations

import gymnasium as gym
from gymnasium.utils.env_checker import check_env
import numpy as np
import pytest

from growspace_sim.agents import OracleAgent, play_episodes
from growspace_sim.core import task as tasks
from growspace_sim.core.chamber import Chamber
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import BEAM_ACTIONS
from growspace_sim.core.state import ChamberState
from growspace_sim.core.task import Layout, Score, Task
from growspace_sim.envs.registration import env_id, register_envs
from growspace_sim.node.episode_runner import EpisodeRunner


def tall_layout(cfg: SimConfig, rng: np.random.Generator) -> Layout:
    """One stem anywhere, the light above it, a target at the top of the chamber."""
    stem = float(rng.uniform(0.2, 0.8)) * cfg.chamber_width
    return Layout((stem,), complex(stem, 0.95 * cfg.chamber_height), light_x=stem)


def tall_score(state: ChamberState, cfg: SimConfig) -> Score:
    """The height of the tallest node, as a fraction of the chamber height."""
    height = float(state.pos[:state.n_nodes].imag.max()) / cfg.chamber_height
    return height, np.array([height]), height >= 0.9


class StayOracle:
    """Keeps the light where it starts, above the stem."""

    def act(self, chamber: Chamber) -> int:
        return BEAM_ACTIONS.index('stay')


TALL = Task(name='grow_tall', env_name='GrowTall', layout=tall_layout, score=tall_score,
            resolution=32, oracle=StayOracle, settings=('easy',))


@pytest.fixture
def tall():
    tasks.register(TALL)
    yield TALL
    tasks.unregister(TALL.name)


def test_the_toy_challenge_is_a_registered_task(tall):
    assert 'grow_tall' in tasks.names()
    assert SimConfig(challenge='grow_tall').task is tall
    with pytest.raises(ValueError, match="setting must be one of \\('easy',\\)"):
        SimConfig(challenge='grow_tall', setting='hard')
    with pytest.raises(ValueError, match='taken'):
        tasks.register(Task(name='grow_tall', env_name='Other', layout=tall_layout,
                            score=tall_score))


def test_unregistered_challenges_are_rejected():
    with pytest.raises(ValueError, match="challenge must be one of .* got 'grow_tall'"):
        SimConfig(challenge='grow_tall')


def test_the_toy_challenge_passes_gymnasium_env_checker(tall):
    ids = register_envs()
    name = env_id('grow_tall', 'easy')
    assert name == 'GrowSpace/GrowTall-Easy-v0' and name in ids
    assert env_id('grow_tall', 'easy', continuous=True) in ids
    env = gym.make(name)
    check_env(env.unwrapped)
    observation, _ = env.reset(seed=3)
    assert observation.shape == (32, 32, 3)
    played = play_episodes(env, OracleAgent(), [3])
    total, info = played.returns[0], played.infos[0]
    chamber = env.unwrapped.chamber
    assert chamber.steps == 50 and info['step'] == 50
    assert info['plant_rewards'][0] == pytest.approx(chamber.nodes[:, 1].max() / 0.84)
    assert 0.0 < total <= 50.0
    env.close()


def test_the_toy_challenge_runs_on_the_in_process_node(tall):
    runner = EpisodeRunner(SimConfig(challenge='control', episode_length=20))
    runner.reset(seed=1)
    played = play_episodes(runner, OracleAgent(), [5], options={'challenge': 'grow_tall'})
    total, steps = played.returns[0], played.steps
    assert steps == 20
    assert runner.node.cfg.task is tall
    assert runner.observation.shape == (32, 32, 3)
    assert runner.result.reward == pytest.approx(runner.chamber.nodes[:, 1].max() / 0.84)
    assert total > 0.0
    again = EpisodeRunner(SimConfig(challenge='grow_tall', episode_length=20))
    replayed = play_episodes(again, OracleAgent(), [5])
    assert (replayed.returns[0], replayed.steps) == (total, steps)  # same seed, same run
    runner.close()
    again.close()


def test_a_recorded_toy_episode_re_simulates_bit_for_bit(tall, tmp_path):
    from growspace_sim import replay  # noqa: PLC0415  (the ROS side: recording and replay)
    from growspace_sim.recording import McapRecorder  # noqa: PLC0415

    path = tmp_path / 'grow_tall.mcap'
    with McapRecorder(path) as recorder:
        runner = EpisodeRunner(SimConfig(challenge='grow_tall', episode_length=15), recorder)
        play_episodes(runner, OracleAgent(), [2, None])
        runner.close()
    report = replay.resimulate(path)
    assert report.ok, report.mismatch
    assert (report.episodes, report.steps) == (2, 30)


# --- tasks that misbehave or leave things out never crash the chamber (issue 24) ------------

def no_target_layout(cfg: SimConfig, rng: np.random.Generator) -> Layout:
    """A stem in the middle and nothing to reach: ``Layout`` allows ``target=None``."""
    return Layout((cfg.chamber_width / 2,), None, light_x=cfg.chamber_width / 2)


def nan_score(state: ChamberState, cfg: SimConfig) -> Score:
    """A broken reward: NaN from the third step on (finite before, as a real bug would be)."""
    reward = float('nan') if state.steps >= 3 else 0.5
    return reward, np.array([reward]), False


BARE = Task(name='bare', env_name='Bare', layout=no_target_layout, score=tall_score,
            oracle=StayOracle, settings=('easy',))
BROKEN = Task(name='broken', env_name='Broken', layout=tall_layout, score=nan_score,
              oracle=StayOracle, settings=('easy',))


@pytest.fixture
def misbehaving():
    tasks.register(BARE)
    tasks.register(BROKEN)
    yield
    tasks.unregister(BARE.name)
    tasks.unregister(BROKEN.name)


def test_a_task_without_a_target_renders_plant_and_light_only(misbehaving):
    register_envs()
    env = gym.make(env_id('bare', 'easy'))
    observation, _ = env.reset(seed=4)
    assert observation[..., 0].max() == 0  # red: the target channel stays empty
    assert observation[..., 1].max() > 0 and observation[..., 2].max() > 0  # plant, light
    for _ in range(5):
        observation, reward, *_ = env.step(BEAM_ACTIONS.index('stay'))
    assert observation[..., 0].max() == 0 and np.isfinite(reward)
    env.close()


def _result_reward_on_the_wire(cdr: bytes) -> float:
    """The reward of a StepResult as its CDR bytes carry it (decoded again, not trusted)."""
    from growspace_sim.ros import types  # noqa: PLC0415

    return float(types.deserialize(cdr, types.STEP_RESULT).reward)


def test_a_nan_reward_ends_the_episode_with_the_reason_and_never_reaches_the_wire(misbehaving):
    from growspace_sim.node.chamber_node import EPISODE_OVER, ChamberNode  # noqa: PLC0415
    from growspace_sim.node.fake import FakeTransport  # noqa: PLC0415
    from growspace_sim.node.params import NodeParams  # noqa: PLC0415
    from growspace_sim.ros import convert, types  # noqa: PLC0415

    transport = FakeTransport(namespace='/chamber1')
    node = ChamberNode(transport, SimConfig(challenge='broken'), NodeParams(seed=3))
    results = transport.published['/chamber1/step_result']
    for step_id in (1, 2, 3, 4):
        transport.inject('light/command', types.new(types.LIGHT_COMMAND, step_id=step_id,
                                                    mode=convert.MODE_DISCRETE, action=2))
    answers = [msg for msg, _ in results]
    assert [(r.step_id, r.truncated) for r in answers] == [(0, False), (1, False), (2, False),
                                                            (3, True), (4, True)]
    assert all(np.isfinite(_result_reward_on_the_wire(cdr)) for _, cdr in results)
    assert answers[2].reward == 0.5 and answers[3].reward == 0.0
    assert 'reward is not finite' in answers[3].info and 'nan' in answers[3].info
    assert answers[4].info == EPISODE_OVER  # the episode is over until a reset
    assert any('reward is not finite' in w for w in transport.warnings)
    # The node lives on: a reset to a sound challenge plays normally.
    transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=1, challenge='control'))
    transport.inject('light/command', types.new(types.LIGHT_COMMAND, step_id=1,
                                                mode=convert.MODE_DISCRETE, action=2))
    assert (results[-1][0].step_id, results[-1][0].info) == (1, '') and node.cfg.task.name == \
        'control'
    node.close()


def test_a_task_whose_first_reward_is_nan_still_starts_the_node(misbehaving):
    from growspace_sim.node.chamber_node import ChamberNode  # noqa: PLC0415
    from growspace_sim.node.fake import FakeTransport  # noqa: PLC0415
    from growspace_sim.node.params import NodeParams  # noqa: PLC0415

    always_nan = Task(name='always_nan', env_name='AlwaysNan', layout=tall_layout,
                      score=lambda state, cfg: (float('nan'), np.array([np.inf]), False),
                      settings=('easy',))
    tasks.register(always_nan)
    try:
        transport = FakeTransport()
        ChamberNode(transport, SimConfig(challenge='always_nan'), NodeParams(seed=1)).close()
    finally:
        tasks.unregister(always_nan.name)
    (result, cdr), = transport.published['/step_result']  # the reset's answer
    assert result.truncated and 'reward is not finite' in result.info
    assert np.isfinite(_result_reward_on_the_wire(cdr)) and np.isfinite(result.plant_rewards).all()


@pytest.mark.parametrize('vector', [False, True])
def test_a_nan_reward_in_process_is_a_clear_error_not_a_quiet_nan(misbehaving, vector):
    # In process the bug surfaces at once (training must not learn from NaN); the node, which
    # must not stop, ends the episode instead (the test above).
    register_envs()
    if vector:
        env = gym.make_vec(env_id('broken', 'easy'), num_envs=2)
        action = np.array([2, 2])
    else:
        env = gym.make(env_id('broken', 'easy'))
        action = 2
    env.reset(seed=1)
    env.step(action)
    env.step(action)
    with pytest.raises(ValueError, match=r'the broken task scored a non-finite reward .*nan.* '
                                         r'at step 3: a bug in its score function'):
        env.step(action)
    env.close()
