"""Reference agents and the evaluation and benchmark scripts."""

from __future__ import annotations

import csv
from pathlib import Path
import os

import gymnasium as gym
import numpy as np
import pytest

from growspace_sim.tools import bench

from growspace_sim.agents import OracleAgent, play_episodes, RandomAgent
from growspace_sim.agents.evaluation import episode_returns
from growspace_sim.envs.registration import env_id
from growspace_sim.tools import evaluate


def test_random_agent_is_seeded():
    env = gym.make('GrowSpace/Control-Easy-v0')
    first, second = RandomAgent(env.action_space, 3), RandomAgent(env.action_space, 3)
    a = [first.act(None, env) for _ in range(20)]
    first.action_space.seed(3)
    b = [second.act(None, env) for _ in range(20)]
    assert a == b and len(set(a)) > 1


@pytest.mark.parametrize('challenge', ('control', 'find_plant', 'fairness', 'shape'))
def test_oracle_returns_valid_actions_and_beats_random_on_average(challenge):
    env = gym.make(env_id(challenge, 'hard'))
    seeds = range(100, 106)
    oracle = play_episodes(env, OracleAgent(), seeds).returns
    random = play_episodes(env, RandomAgent(env.action_space, 0), seeds).returns
    assert np.mean(oracle) > np.mean(random)


def test_oracle_refuses_continuous_envs():
    env = gym.make('GrowSpace/ControlContinuous-Easy-v0')
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match='discrete'):
        OracleAgent().act(obs, env)


def test_eval_script_writes_the_expected_columns(tmp_path, capsys):
    out = tmp_path / 'eval.csv'
    assert evaluate.main(['--episodes', '2', '--challenges', 'control,shape',
                          '--settings', 'easy', '--csv', str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [r['challenge'] for r in rows] == ['control', 'shape']
    assert list(rows[0]) == list(evaluate.COLUMNS)
    assert all(float(r['random_se']) >= 0 for r in rows)
    table = capsys.readouterr().out
    assert '| challenge | setting | random | oracle | oracle success |' in table


def test_eval_script_rejects_unknown_challenges():
    with pytest.raises(SystemExit):
        evaluate.main(['--episodes', '2', '--challenges', 'growing'])


@pytest.mark.slow
def test_bench_script_prints_a_table_and_restores_the_cpu_set(capsys):
    cpus = os.sched_getaffinity(0)
    assert bench.main(['--episodes', '1', '--repeats', '1', '--challenges', 'control']) == 0
    out = capsys.readouterr().out
    assert '| control |' in out and 'peak RSS' in out
    assert os.sched_getaffinity(0) == cpus


@pytest.mark.slow
def test_the_readme_evaluation_table_reproduces_exactly(capsys):
    # The README's table is `growspace-eval --episodes 100`, printed by the one evaluation stack.
    readme = (Path(__file__).resolve().parents[2] / 'README.md').read_text()
    assert evaluate.main(['--episodes', '100']) == 0
    table = capsys.readouterr().out.split('\n\n', 1)[1].strip()
    assert table in readme


def test_a_challenge_without_an_oracle_is_evaluated_without_one():
    from growspace_sim.core.task import Layout, register, Task, unregister
    from growspace_sim.envs.registration import register_envs

    task = register(Task(name='no_oracle', env_name='NoOracle', settings=('easy',),
                         layout=lambda cfg, rng: Layout((0.42,), complex(0.42, 0.7), 0.42),
                         score=lambda state, cfg: (0.5, np.array([0.5]), False)))
    try:
        register_envs()
        row = evaluate.evaluate('no_oracle', 'easy', episodes=2)
        assert row.random_mean == 25.0 and row.oracle_mean != row.oracle_mean  # NaN: none
        assert '- (no oracle)' in evaluate.markdown([row])
    finally:
        unregister(task.name)


def test_returns_are_added_in_step_order_on_every_python():
    """Python 3.12's sum() compensates (1.0 here) and numpy's is pairwise; an agent adding its
    rewards one by one gets 0.0, and so must every report of the episode (CI on 3.12 failed the
    pinned return hash when a report used sum())."""
    rows = np.array([[1e16, 1.0, -1e16], [0.1, 0.2, 0.3]])
    assert episode_returns(rows).tolist() == [0.0, (0.1 + 0.2) + 0.3]
