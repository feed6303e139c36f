"""The growth core: determinism, invariants on every step, known answers, rewards, validation."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from growspace_sim.core import chamber as chamber_module, light as lights
from growspace_sim.core import task as tasks
from growspace_sim.core.chamber import Chamber
from growspace_sim.core.config import SimConfig
from growspace_sim.core.errors import CommandError
from growspace_sim.core.tasks import distance_reward, jaccard

from conftest import child_env

CHALLENGES = ('control', 'find_plant', 'fairness', 'shape')  # the built-in tasks
ALL_CASES = [(c, s) for c in CHALLENGES for s in tasks.SETTINGS]
DIGIT = np.zeros((28, 28), np.uint8)
DIGIT[6:22, 11:17] = 255  # a hand-made '1': tests use data the project makes


def make(challenge: str = 'control', setting: str = 'easy', **overrides) -> Chamber:
    return Chamber(SimConfig(challenge=challenge, setting=setting, **overrides))


def rollout(chamber: Chamber, seed: int, check=None) -> list[float]:
    """A 50-step episode with seeded random discrete actions; `check` runs after every step."""
    rng = np.random.default_rng(seed)
    chamber.reset(rng, DIGIT if chamber.cfg.challenge == 'shape' else None)
    n_actions = len(lights.SPOT_ACTIONS if chamber.light.spot else lights.BEAM_ACTIONS)
    actions = np.random.default_rng(seed + 1).integers(n_actions, size=chamber.cfg.episode_length)
    rewards = []
    for action in actions:
        before = (chamber.n_nodes, chamber.photons.size)
        lights.apply_discrete(chamber.light, int(action), chamber.cfg)
        outcome = chamber.step()
        rewards.append(outcome.reward)
        if check:
            check(chamber, outcome, before)
    return rewards


def snapshot(chamber: Chamber) -> tuple:
    n = chamber.n_nodes
    return (chamber.pos[:n].copy(), chamber.parent[:n].copy(), chamber.photons.copy(),
            chamber.occupancy.copy(), chamber.light.copy())


# ---------------------------------------------------------------- determinism
@pytest.mark.parametrize('challenge,setting', ALL_CASES)
def test_same_seed_gives_identical_episodes(challenge, setting):
    a, b = make(challenge, setting), make(challenge, setting)
    rewards_a, rewards_b = rollout(a, 7), rollout(b, 7)
    assert rewards_a == rewards_b
    for x, y in zip(snapshot(a), snapshot(b)):
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y)
        else:
            assert x == y


@pytest.mark.parametrize('challenge', CHALLENGES)
def test_different_seeds_give_different_episodes(challenge):
    a, b = make(challenge), make(challenge)
    rollout(a, 1)
    rollout(b, 2)
    assert not np.array_equal(a.photons, b.photons)
    assert a.n_nodes != b.n_nodes or not np.array_equal(a.pos[:a.n_nodes], b.pos[:b.n_nodes])


@pytest.mark.slow
def test_episode_is_reproducible_across_processes():
    code = ('import numpy as np, hashlib\n'
            'from test_core import make, rollout\n'
            'c = make("fairness", "hard")\n'
            'r = rollout(c, 11)\n'
            'print(hashlib.sha256(c.pos[:c.n_nodes].tobytes() + np.array(r).tobytes())'
            '.hexdigest())\n')
    here = make('fairness', 'hard')
    rewards = rollout(here, 11)
    import hashlib
    expected = hashlib.sha256(here.pos[:here.n_nodes].tobytes()
                              + np.array(rewards).tobytes()).hexdigest()
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         env=child_env(), timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == expected


# ---------------------------------------------------------------- invariants
def check_invariants(chamber: Chamber, outcome, before) -> None:
    cfg = chamber.cfg
    n = chamber.n_nodes
    pos, parent = chamber.pos[:n], chamber.parent[:n]
    assert np.isfinite(pos).all()
    assert (pos.real >= 0).all() and (pos.real <= cfg.chamber_width).all()
    assert (pos.imag >= 0).all() and (pos.imag <= cfg.chamber_height).all()
    grown = np.flatnonzero(parent >= 0)
    assert (parent[grown] < grown).all()
    lengths = np.abs(pos[grown] - pos[parent[grown]])
    stems = parent[grown] < cfg.plant_count  # the initial stems start at the roots
    np.testing.assert_allclose(lengths[stems], cfg.width_m(cfg.first_branch_height))
    np.testing.assert_allclose(lengths[~stems], cfg.branch_length_m, rtol=1e-12)
    assert (chamber.plant[grown] == chamber.plant[parent[grown]]).all()
    assert n >= before[0] and n - before[0] <= cfg.max_branching
    assert n - before[0] == outcome.new_segments
    assert chamber.photons.size <= before[1]
    assert 0.0 < outcome.reward <= 1.0 if cfg.challenge != 'shape' else 0 <= outcome.reward <= 1
    assert np.isfinite(outcome.plant_rewards).all()
    # descendant counts and tips agree with a brute-force walk of the tree
    brute = np.zeros(n, int)
    for i in grown:
        p = parent[i]
        while p >= 0:
            brute[p] += 1
            p = parent[p]
    np.testing.assert_array_equal(chamber.descendants, brute)
    np.testing.assert_array_equal(chamber.tips(), np.setdiff1d(np.arange(n), parent[grown]))
    np.testing.assert_array_equal(chamber.branch_counts(),
                                  np.bincount(chamber.plant[grown], minlength=cfg.plant_count))


@pytest.mark.parametrize('challenge,setting', ALL_CASES)
@pytest.mark.parametrize('seed', [0, 1, 2])
def test_invariants_hold_on_every_step(challenge, setting, seed):
    chamber = make(challenge, setting)
    rollout(chamber, seed, check_invariants)
    assert chamber.steps == chamber.cfg.episode_length


def test_descendant_counts_hold_in_trees_deeper_than_the_ancestor_window(monkeypatch):
    """A node deeper than the window reaches its far ancestors through older rows."""
    monkeypatch.setattr(chamber_module, 'ANCESTOR_WINDOW', 3)
    chamber = make('control', episode_length=60, light_density=2000, max_branching=3)
    rollout(chamber, 4, check_invariants)
    depth = np.zeros(chamber.n_nodes, int)
    for i in range(chamber.n_nodes):
        depth[i] = depth[chamber.parent[i]] + 1 if chamber.parent[i] >= 0 else 0
    assert depth.max() > 4 * 3  # several windows deep


def test_plant_grows_under_random_light():
    sizes = []
    for seed in range(5):
        chamber = make('control')
        rollout(chamber, seed)
        sizes.append(chamber.branch_counts()[0])
    assert np.mean(sizes) > 10  # the benchmark reports ~45 segments at step 50


def test_stepping_past_the_episode_raises():
    chamber = make(episode_length=2)
    chamber.reset(np.random.default_rng(0))
    chamber.step()
    assert chamber.step().truncated
    with pytest.raises(RuntimeError, match='episode is over'):
        chamber.step()


# ---------------------------------------------------------------- known answers
def single_stem(**overrides) -> Chamber:
    """A control chamber whose stem tip is at a known place, with no photons yet."""
    chamber = make('control', light_width=0.5, **overrides)
    chamber.reset(np.random.default_rng(3))
    chamber.set_photons(np.zeros(0))
    return chamber


def test_one_photon_above_the_tip_grows_it_straight_up():
    chamber = single_stem()
    tip = chamber.pos[chamber.n_nodes - 1]
    lights.set_absolute(chamber.light, chamber.cfg, tip.real, 0.0, chamber.light.width, 0.1)
    chamber.set_photons([tip + 0.1j])
    outcome = chamber.step()
    assert outcome.new_segments == 1
    new = chamber.pos[chamber.n_nodes - 1]
    assert new == pytest.approx(tip + 1j * chamber.cfg.branch_length_m, abs=1e-12)
    assert chamber.parent[chamber.n_nodes - 1] == chamber.n_nodes - 2


def test_growth_follows_the_normalised_sum_of_unit_vectors():
    chamber = single_stem()
    tip = chamber.pos[chamber.n_nodes - 1]
    lights.set_absolute(chamber.light, chamber.cfg, tip.real, 0.0, chamber.light.width, 0.1)
    chamber.set_photons([tip + 0.1j, tip + 0.1])  # up and right: grow at 45 degrees
    chamber.step()
    step = chamber.cfg.branch_length_m / np.sqrt(2)
    assert chamber.pos[chamber.n_nodes - 1] == pytest.approx(tip + step + 1j * step, abs=1e-12)


def test_photons_outside_the_light_or_beyond_reach_do_not_attract():
    chamber = single_stem()
    tip = chamber.pos[chamber.n_nodes - 1]
    far = chamber.cfg.width_m(chamber.cfg.radius_of_influence) * 1.01
    chamber.set_photons([tip + 1j * far])
    assert chamber.step().new_segments == 0
    chamber = single_stem()
    lights.set_absolute(chamber.light, chamber.cfg, 0.7, 0.0, chamber.cfg.width_m(0.1), 0.1)
    chamber.set_photons([tip + 0.05j])  # close, but not under the beam
    assert chamber.step().new_segments == 0


def test_a_photon_is_used_up_by_a_node_that_reaches_it():
    chamber = single_stem()
    tip = chamber.pos[chamber.n_nodes - 1]
    lights.set_absolute(chamber.light, chamber.cfg, tip.real, 0.0, chamber.light.width, 0.1)
    chamber.set_photons([tip + 1j * chamber.cfg.branch_length_m * 1.2])
    chamber.step()
    assert chamber.photons.size == 0  # the new node is 0.2 branch lengths from it


@pytest.mark.parametrize('shading, grows', [(True, 0), (False, 1)])
def test_a_photon_under_a_leaf_is_not_lit(shading, grows):
    chamber = single_stem(shading=shading)
    cfg = chamber.cfg
    tip = chamber.pos[chamber.n_nodes - 1]
    lights.set_absolute(chamber.light, cfg, tip.real + 0.05, 0.0, chamber.light.width, 0.1)
    chamber.set_photons([tip + 0.1])  # grow a horizontal leaf to the right
    assert chamber.step().new_segments == 1
    leaf = chamber.pos[chamber.n_nodes - 1]
    assert leaf == pytest.approx(tip + cfg.branch_length_m, abs=1e-12)
    under = tip + 0.5 * cfg.branch_length_m - 0.05j  # below the leaf's middle, in reach
    chamber.set_photons([under])
    assert chamber.shaded.tolist() == [True]  # geometry; the flag only decides if it counts
    assert chamber.step().new_segments == grows


def test_at_most_max_branching_buds_grow_per_step():
    chamber = make('control', max_branching=2, light_width=0.5)
    chamber.reset(np.random.default_rng(0))
    rng = np.random.default_rng(5)
    tip = chamber.pos[chamber.n_nodes - 1]
    for _ in range(3):  # build a few buds first
        chamber.set_photons(tip + rng.uniform(-0.1, 0.1, 30) + 1j * rng.uniform(0.0, 0.12, 30))
        assert chamber.step().new_segments <= 2


# ---------------------------------------------------------------- rewards
def test_distance_reward_known_values():
    assert distance_reward(0.0, 0.1) == 1.0
    assert distance_reward(0.05, 0.1) == 1.0
    assert distance_reward(0.2, 0.1) == pytest.approx(0.5)
    assert distance_reward(1.0, 0.1) == pytest.approx(0.1)


@pytest.mark.parametrize('challenge', ['control', 'find_plant', 'fairness'])
def test_target_reward_is_the_brute_force_formula(challenge):
    chamber = make(challenge)
    rollout(chamber, 4)
    cfg = chamber.cfg
    unit = cfg.width_m(cfg.target_radius)
    n = chamber.n_nodes
    grown = chamber.parent[:n] >= 0
    per_plant = []
    for p in range(cfg.plant_count):
        nodes = chamber.pos[:n][grown & (chamber.plant[:n] == p)]
        per_plant.append(min(1.0, unit / np.abs(nodes - chamber.target).min()))
    outcome = chamber.current_reward()
    np.testing.assert_allclose(outcome.plant_rewards, per_plant)
    assert outcome.reward == pytest.approx(min(per_plant))  # fairness: the worst plant
    assert 0.0 < outcome.reward <= 1.0


def test_jaccard_known_values():
    a = np.zeros((4, 4), bool)
    b = np.zeros((4, 4), bool)
    assert jaccard(a, b) == 0.0
    a[0, :2] = True
    b[0, 1:3] = True
    assert jaccard(a, b) == pytest.approx(1 / 3)
    assert jaccard(a, a) == 1.0
    assert jaccard(a, ~a) == 0.0


def test_a_plant_covering_the_digit_exactly_scores_one():
    chamber = make('shape')
    state = chamber.reset(np.random.default_rng(0), DIGIT)
    state.occupancy[:] = state.target_mask  # a crafted plant with exactly the digit's pixels
    reward, plant_rewards, success = chamber.task.score(state, chamber.cfg)
    assert reward == 1.0 and plant_rewards.tolist() == [1.0] and success


def test_shape_reward_counts_plant_pixels_not_light_pixels():
    chamber = make('shape')
    chamber.reset(np.random.default_rng(0), DIGIT)
    lights.set_absolute(chamber.light, chamber.cfg, 0.42, 0.42, 0.1, 0.25)  # light on the digit
    plant = chamber.occupancy
    expected = (plant & chamber.target_mask).sum() / (plant | chamber.target_mask).sum()
    assert chamber.current_reward().reward == pytest.approx(expected)
    assert expected < 0.2


# ---------------------------------------------------------------- the light
def test_discrete_actions_move_by_one_light_step_and_clamp():
    cfg = SimConfig()
    light = lights.initial_light(cfg, 0.42, 0.0)
    lights.apply_discrete(light, lights.BEAM_ACTIONS.index('right'), cfg)
    assert light.x == pytest.approx(0.42 + 5 / 84 * 0.84)
    for _ in range(100):
        lights.apply_discrete(light, lights.BEAM_ACTIONS.index('right'), cfg)
    assert light.x + light.width / 2 == pytest.approx(cfg.chamber_width)
    for _ in range(100):
        lights.apply_discrete(light, lights.BEAM_ACTIONS.index('wider'), cfg)
    assert light.width == pytest.approx(cfg.width_m(cfg.light_width_max))
    assert light.x + light.width / 2 <= cfg.chamber_width + 1e-12


def test_continuous_actions_map_onto_the_limits():
    cfg = SimConfig(challenge='shape')
    light = lights.initial_light(cfg, 0.42, 0.42)
    lights.apply_continuous(light, np.array([1.0, -1.0, 1.0]), cfg)
    assert light.radius == pytest.approx(cfg.width_m(cfg.spot_radius_max))
    assert light.x == pytest.approx(0.42 + cfg.light_step_m)
    assert light.z == pytest.approx(0.42 - cfg.light_step_m)


@pytest.mark.parametrize('action, message', [
    (5, r'action = 5 is not allowed; expected an int in \[0, 4\] \(left, right,'),
    (-1, 'action = -1 '), (1.5, 'action = 1.5 '), (True, 'action = True ')])
def test_bad_discrete_actions_are_rejected(action, message):
    cfg = SimConfig()
    light = lights.initial_light(cfg, 0.42, 0.0)
    with pytest.raises(CommandError, match=message) as err:
        lights.apply_discrete(light, action, cfg)
    assert (err.value.field, err.value.value) == ('action', action)


@pytest.mark.parametrize('action, message', [
    ([0.0], r'continuous = \[0.0\] is not allowed; expected 2 values'),
    ([np.nan, 0.0], r'continuous\[0\] = nan is not allowed'),
    ([0.0, 1.5], r'continuous\[1\] = 1.5 is not allowed; expected a finite number in \[-1, 1\]')])
def test_bad_continuous_actions_are_rejected(action, message):
    cfg = SimConfig()
    light = lights.initial_light(cfg, 0.42, 0.0)
    before = light.copy()
    with pytest.raises(ValueError, match=message):
        lights.apply_continuous(light, action, cfg)
    assert light == before


def test_absolute_light_commands_reject_non_finite_values():
    cfg = SimConfig()
    light = lights.initial_light(cfg, 0.42, 0.0)
    with pytest.raises(CommandError, match='x = nan is not allowed; expected a finite number'):
        lights.set_absolute(light, cfg, float('nan'), 0.0, 0.2, 0.1)


# ---------------------------------------------------------------- configuration
BAD_VALUES = {
    'challenge': 'grow', 'setting': 'medium', 'chamber_width': 0.0, 'chamber_height': -1.0,
    'image_size': 3, 'episode_length': 0, 'light_density': 0, 'photon_min_height': 1.5,
    'first_branch_height': 0.0, 'branch_length': -0.1, 'branch_thickness': 2.0,
    'max_branching': 0, 'radius_of_influence': 0.0, 'kill_distance': float('nan'),
    'light_width': 0.9, 'light_width_min': 0.0, 'light_width_max': 1.5, 'light_step_px': 0.0,
    'spot_radius': 0.5, 'spot_radius_min': 0.0, 'spot_radius_max': 2.0, 'shading': 'yes',
    'target_radius': 0.0, 'n_plants': 0, 'digits': (3, 11), 'shape_success': 0.0,
}


def test_every_field_has_a_bad_value_case():
    assert set(BAD_VALUES) == {f.name for f in dataclasses.fields(SimConfig)}


@pytest.mark.parametrize('field, value', sorted(BAD_VALUES.items(), key=lambda kv: kv[0]))
def test_invalid_parameters_name_the_field_and_value(field, value):
    with pytest.raises(ValueError, match=field) as error:
        SimConfig(**{field: value})
    assert repr(value) in str(error.value) or str(value) in str(error.value)


def test_cross_field_rules():
    with pytest.raises(ValueError, match='kill_distance .* must be lower than radius'):
        SimConfig(kill_distance=0.2, radius_of_influence=0.1)
    with pytest.raises(ValueError, match='n_plants must be at least 2 for fairness'):
        SimConfig(challenge='fairness', n_plants=1)
    with pytest.raises(ValueError, match='Unknown parameter'):
        SimConfig.from_dict({'branch_lenght': 0.1})
    with pytest.raises(ValueError, match=r'max_branching x episode_length \(100 x 100000 = '
                                         r'10000000\) must be in \[1, 2000000\]'):
        SimConfig(max_branching=100, episode_length=100_000)


@pytest.mark.parametrize('field, value, allowed', [
    ('episode_length', 100_001, r'\[1, 100000\]'), ('max_branching', 101, r'\[1, 100\]'),
    ('light_density', 100_001, r'\[1, 100000\]'),
    ('branch_thickness', 0.0005, r'\[0.001, 1.0\]')])
def test_bounds_keep_an_episode_on_a_small_machine(field, value, allowed):
    with pytest.raises(ValueError, match=f'{field} must be in {allowed}, got {value}'):
        SimConfig(**{field: value})
    SimConfig(episode_length=20_000, light_density=12_800)  # the rows are accepted


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='reads /proc/self/status')
@pytest.mark.slow
def test_long_episodes_reset_in_linear_memory():
    """Issue 10: episode_length 20,000 used to need an 11.9 GiB ancestors table. Memory only:
    reset time is the benchmark's business (growspace-bench prints it), not a unit test's.
    The kernels are loaded first (numba, LLVM and, where installed, scipy, which numba imports:
    about 60 MiB whatever the episode), so what is measured is the episode's own memory."""
    code = ('import numpy as np\n'
            'from growspace_sim.core.chamber import Chamber\n'
            'from growspace_sim.core.config import SimConfig\n'
            'def peak():  # kB; ru_maxrss would include the parent (it survives exec)\n'
            '    return int(open("/proc/self/status").read().split("VmHWM:")[1].split()[0])\n'
            'w = Chamber(SimConfig(episode_length=2, light_density=8))\n'
            'w.reset(np.random.default_rng(0))\n'
            'w.step()\n'
            'before = peak()\n'
            'c = Chamber(SimConfig(episode_length=20_000, light_density=12_800))\n'
            'c.reset(np.random.default_rng(0))\n'
            'c.reset(np.random.default_rng(1))\n'
            'for _ in range(200): c.step()\n'
            'print((peak() - before) / 1024)\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         env=child_env(), timeout=120)
    assert out.returncode == 0, out.stderr
    assert float(out.stdout) < 25.0  # MiB for two resets and 200 steps of a 20,000-step episode


def test_config_from_dict_accepts_ros_lists():
    cfg = SimConfig.from_dict({'challenge': 'shape', 'digits': [3, 6]})
    assert cfg.digits == (3, 6) and cfg.resolution == 28


@pytest.mark.slow
def test_core_imports_without_ros_or_opencv():
    code = ('import sys\n'
            'sys.modules["rclpy"] = None\n'
            'sys.modules["cv2"] = None\n'
            'import growspace_sim.core as core\n'
            'import numpy as np\n'
            'c = core.Chamber(core.SimConfig())\n'
            'c.reset(np.random.default_rng(0))\n'
            'c.step()\n'
            'print("ok")\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         env=child_env(), timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == 'ok'
