"""In-process Gymnasium environments for the four GrowSpace challenges."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from growspace_sim import digits as digit_data
from growspace_sim.core import light as lights
from growspace_sim.core.chamber import Chamber, StepOutcome
from growspace_sim.core.config import SimConfig
from growspace_sim.simulation import Simulation

OBSERVATIONS = ('rgb', 'features')


class GrowSpaceEnv(gym.Env):
    """Steer a plant grown by the Space Colonization Algorithm by moving a light.

    ## Description
    A chamber (default 0.84 m x 0.84 m) holds photons scattered at random above 25% of its
    height, one plant (n >= 2 in ``fairness``) and a light. Each step, the buds of the plant
    nearest to lit photons grow one segment towards them (see ``growspace_sim.core.chamber``).
    The action moves the light first, so it acts in the step it is given.

    ## Action Space
    Beam challenges (``control``, ``find_plant``, ``fairness``): ``Discrete(5)``

    | action | effect |
    |---|---|
    | 0 | move left by ``light_step_px`` (5 px of 84 = 0.05 m by default) |
    | 1 | move right |
    | 2 | stay |
    | 3 | widen by one light step (up to ``light_width_max``, 0.5 of the width) |
    | 4 | narrow by one light step (down to ``light_width_min``, 0.1 of the width) |

    ``shape`` uses a spotlight: ``Discrete(7)`` = left, right, up, down, bigger (+half a step of
    radius), smaller, stay. With ``continuous=True`` the space is ``Box(-1, 1, (2,))`` =
    (velocity in light steps, width mapped onto [min, max]) for the beam and ``Box(-1, 1, (3,))``
    = (dx, dz in light steps, radius mapped onto [min, max]) for the spotlight.

    ## Observation Space
    ``Box(0, 255, (84, 84, 3), uint8)`` RGB (28 x 28 for ``shape``): red = target, green = plant,
    blue = light (128). With ``observation='features'`` the same planes as {0, 1}.

    ## Rewards
    - control, find_plant: ``max over the plant's nodes of 1/d``, d = distance to the target
      centre in target radii (0.0252 m by default), floored at 1 so the reward is in ]0, 1]
      (``core.tasks.distance_reward`` explains why).
    - fairness: the minimum of that reward over the plants.
    - shape: Jaccard index of the plant's pixels and the digit's pixels (the light is not part
      of either).

    ## Starting State
    A stem of ``first_branch_height`` stands on the floor. control/find_plant easy: the target
    (upper 25% of the chamber) is above the stem; hard: stem and target at opposite sides.
    control starts the light above the stem, find_plant and fairness anywhere. fairness easy: the
    plants stand one light width apart with the target between them; hard: at opposite walls,
    target in the middle. shape: the stem is centred under a 28 x 28 MNIST digit (easy 3, hard 0).

    ## Episode End
    Truncation after ``episode_length`` (50) steps; there is no terminal state.

    ## Arguments
    ``challenge``, ``setting``, ``continuous``, ``observation`` ('rgb' | 'features'),
    ``render_mode`` ('rgb_array'), ``digit_source`` (see ``growspace_sim.digits.load_digits``),
    ``config`` (a ``SimConfig``) and any ``SimConfig`` field as a keyword override.

    ## Info
    ``tips`` (tuple per plant of (K, 2) tip positions in m), ``branch_counts`` (segments per
    plant), ``plant_rewards``, ``light`` (x, z, width, radius in m), ``success``, ``step`` and,
    for shape, ``digit``.
    """

    metadata = {'render_modes': ['rgb_array'], 'render_fps': 10}

    def __init__(self, challenge: str = 'control', setting: str = 'easy', *,
                 continuous: bool = False, observation: str = 'rgb',
                 render_mode: str | None = None, digit_source: str = 'auto',
                 config: SimConfig | None = None, **overrides: Any) -> None:
        check_env_args(observation, render_mode)
        self.cfg = (config or SimConfig()).replace(challenge=challenge, setting=setting,
                                                   **overrides)
        self.continuous = continuous
        self.observation = observation
        self.render_mode = render_mode
        self.sim = Simulation(self.cfg, digit_source)
        self.action_space, self.observation_space = spaces_for(self.cfg, continuous, observation)

    @property
    def chamber(self) -> Chamber:
        """The simulated chamber (privileged state, for oracles and tests)."""
        return self.sim.chamber

    def set_target_digits(self, digits: Sequence[int]) -> None:
        """Draw shape targets from these digits from the next reset on (curriculum learning)."""
        self.sim.set_target_digits(digits)

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        outcome = self.sim.reset(rng=self.np_random)
        return self._observe(), self._info(outcome)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self.continuous:
            self.sim.apply_continuous(action)
        else:
            self.sim.apply_discrete(as_action_index(action))
        outcome = self.sim.step()
        check_rewards(outcome.reward, self.cfg, self.chamber.steps)
        return self._observe(), outcome.reward, False, outcome.truncated, self._info(outcome)

    def render(self) -> np.ndarray | None:
        if self.render_mode == 'rgb_array':
            return self.sim.observe()
        return None

    def _observe(self) -> np.ndarray:
        return self.sim.observe(features=self.observation == 'features')

    def _info(self, outcome: StepOutcome) -> dict[str, Any]:
        chamber = self.chamber
        light = chamber.light
        info = {
            'step': chamber.steps,
            'tips': tuple(tips.copy() for tips in chamber.tip_positions()),
            'branch_counts': chamber.branch_counts(),
            'plant_rewards': outcome.plant_rewards,
            'light': {'x': light.x, 'z': light.z, 'width': light.width, 'radius': light.radius},
            'success': outcome.success,
        }
        if self.sim.digit is not None:
            info['digit'] = self.sim.digit
        return info


def check_rewards(rewards: Any, cfg: SimConfig, step: int) -> None:
    """Refuse a non-finite reward: a bug in the task's score, which training must not learn
    from quietly (the chamber node, which must not stop, ends such an episode instead and says
    why in ``StepResult.info``).

    Raises:
        ValueError: naming the challenge, the reward and the step.
    """
    finite = math.isfinite(rewards) if isinstance(rewards, float) else np.isfinite(rewards).all()
    if not finite:  # (math for one env's float: numpy's call costs ~1 us a step)
        raise ValueError(f'the {cfg.challenge} task scored a non-finite reward ({rewards!r}) at '
                         f'step {step}: a bug in its score function.')


def check_env_args(observation: str, render_mode: str | None) -> None:
    """Check the arguments every GrowSpace env takes (in process, vector, bridged).

    Raises:
        ValueError: naming the argument, its value and what is allowed.
    """
    if observation not in OBSERVATIONS:
        raise ValueError(f'observation must be one of {OBSERVATIONS}, got {observation!r}.')
    if render_mode not in (None, 'rgb_array'):
        raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}.")


def spaces_for(cfg: SimConfig, continuous: bool,
               observation: str = 'rgb') -> tuple[gym.spaces.Space, gym.spaces.Box]:
    """The action and observation spaces of a chamber (shared with the ROS bridge)."""
    spot = cfg.uses_spotlight
    if continuous:
        action_space: gym.spaces.Space = gym.spaces.Box(-1.0, 1.0, (3 if spot else 2,),
                                                        np.float32)
    else:
        action_space = gym.spaces.Discrete(len(lights.SPOT_ACTIONS if spot
                                               else lights.BEAM_ACTIONS))
    side = cfg.resolution
    high = 255 if observation == 'rgb' else 1
    return action_space, gym.spaces.Box(0, high, (side, side, 3), np.uint8)


def as_action_index(action: Any) -> Any:
    """Accept numpy scalars and 0-d / 1-element arrays, as vector envs and SB3 pass them."""
    if isinstance(action, np.ndarray) and action.shape in ((), (1,)):
        return action.reshape(()).item()
    return action


class DigitCurriculum(gym.Wrapper):
    """The shape challenge's MNIST curriculum: digits join in the paper's order of difficulty.

    Stage k (starting at 1) draws targets from ``CURRICULUM_ORDER[:k]`` (3, 6, 2, 1, 4, 5, 7,
    8, 9, 0); a new stage begins every ``episodes_per_stage`` resets until all ten digits are in.
    """

    def __init__(self, env: gym.Env, episodes_per_stage: int = 100) -> None:
        super().__init__(env)
        if episodes_per_stage < 1:
            raise ValueError(f'episodes_per_stage must be >= 1, got {episodes_per_stage}.')
        self.episodes_per_stage = episodes_per_stage
        self.episodes = 0

    @property
    def stage(self) -> int:
        return min(1 + self.episodes // self.episodes_per_stage, len(digit_data.CURRICULUM_ORDER))

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict]:
        self.env.unwrapped.set_target_digits(digit_data.CURRICULUM_ORDER[:self.stage])
        self.episodes += 1
        return self.env.reset(**kwargs)


def make_curriculum(episodes_per_stage: int = 100, **kwargs: Any) -> gym.Env:
    """An environment of a challenge with shape targets wrapped in ``DigitCurriculum`` (the
    entry point its task registers, e.g. ``GrowSpace/Shape-Curriculum-v0`` with ``challenge``
    ``shape``)."""
    return DigitCurriculum(GrowSpaceEnv(**kwargs), episodes_per_stage)
