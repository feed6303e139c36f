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
