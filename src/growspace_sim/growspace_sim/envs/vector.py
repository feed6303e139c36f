"""N GrowSpace chambers stepped in one process: Gymnasium's native vector environment.

``gymnasium.make_vec(id, num_envs=N, vectorization_mode='vector_entry_point')`` builds a
``GrowSpaceVectorEnv`` for every GrowSpace id (``registration``). It plays the same episodes as
N ``GrowSpaceEnv`` with the seeds ``seed, seed + 1, ...`` under ``SyncVectorEnv`` (tested), and
saves what a vector of Python envs pays per step: wrappers, per-env info dictionaries and their
merging, and one array per observation.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space
import numpy as np

from growspace_sim import digits as digit_data
from growspace_sim.core.chamber import Chamber, StepOutcome
from growspace_sim.core.config import SimConfig
from growspace_sim.envs.env import check_env_args, check_rewards, spaces_for
from growspace_sim.simulation import Simulation

LIGHT_KEYS = ('x', 'z', 'width', 'radius')


class GrowSpaceVectorEnv(gym.vector.VectorEnv):
    """``num_envs`` chambers of one challenge, stepped together (see ``GrowSpaceEnv``).

    ## Action Space
    ``MultiDiscrete([n] * num_envs)`` (n = 5 for the beam, 7 for the spotlight), or with
    ``continuous=True`` a ``Box(-1, 1, (num_envs, 2 or 3))``: one ``GrowSpaceEnv`` action per
    chamber.

    ## Observation Space
    ``Box(0, 255, (num_envs, size, size, 3), uint8)``: each chamber's RGB image (or {0, 1}
    feature maps), a new array per call.

    ## Autoreset
    ``autoreset_mode`` (``metadata['autoreset_mode']``) is Gymnasium's ``AutoresetMode``:
    ``NEXT_STEP`` (default): the step after a chamber's episode ends ignores its action, resets
    it (its random stream continues) and returns the first observation with reward 0;
    ``SAME_STEP``: the ending step resets at once and puts the last observation and info in
    ``info['final_obs']`` and ``info['final_info']`` (masks ``_final_obs``, ``_final_info``);
    ``DISABLED``: reset the ended chambers yourself, ``reset(options={'reset_mask': mask})``.

    ## Info
    Arrays over the chambers, each with its ``_key`` mask as Gymnasium's vector envs give them:
    ``step`` (N,) int, ``success`` (N,) bool, ``plant_rewards`` and ``branch_counts``
    (N, plants), ``light`` (a dict of (N,) arrays: x, z, width, radius in m) and, for shape,
    ``digit``. The per-plant tip positions of ``GrowSpaceEnv``'s info are not batched:
    read ``chambers[i].tip_positions()``.

    ## Arguments
    ``num_envs``, ``autoreset_mode`` and ``episodes_per_stage`` (the shape curriculum of
    ``DigitCurriculum``, counted per chamber: digits join in the paper's order every that many
    resets of a chamber), then as ``GrowSpaceEnv``: ``challenge``, ``setting``, ``continuous``,
    ``observation``, ``render_mode``, ``digit_source``, ``config`` and any ``SimConfig`` field
    as a keyword override.
    """

    metadata = {'render_modes': ['rgb_array'], 'render_fps': 10,
                'autoreset_mode': AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, challenge: str = 'control', setting: str = 'easy', *,
                 continuous: bool = False, observation: str = 'rgb',
                 render_mode: str | None = None, digit_source: str = 'auto',
                 config: SimConfig | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 episodes_per_stage: int | None = None, **overrides: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) \
                or num_envs < 1:
            raise ValueError(f'num_envs must be an int >= 1, got {num_envs!r}.')
        check_env_args(observation, render_mode)
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError as e:
            raise ValueError(f'autoreset_mode must be one of '
                             f'{[m.value for m in AutoresetMode]}, got {autoreset_mode!r}.') from e
        self.metadata = {**type(self).metadata, 'autoreset_mode': self.autoreset_mode}
        self.cfg = (config or SimConfig()).replace(challenge=challenge, setting=setting,
                                                   **overrides)
        self.num_envs = int(num_envs)
        self.continuous = continuous
        self.observation = observation
        self.render_mode = render_mode
        self.sims = [Simulation(self.cfg, digit_source) for _ in range(self.num_envs)]
        self.single_action_space, self.single_observation_space = spaces_for(
            self.cfg, continuous, observation)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._ended = np.zeros(self.num_envs, bool)  # episode over: autoreset pending
        self._digits = self.cfg.task.digits is not None  # shape targets: info names the digit
        self._zeros = np.zeros(self.cfg.plant_count)  # the info of a chamber without news
        self._zero_counts = np.zeros(self.cfg.plant_count, np.int64)
        self._chambers = tuple(sim.chamber for sim in self.sims)
        self._started = False
        if episodes_per_stage is not None and (
                not self._digits or isinstance(episodes_per_stage, bool)
                or not isinstance(episodes_per_stage, (int, np.integer))
                or episodes_per_stage < 1):
            raise ValueError(f'episodes_per_stage must be None or >= 1 with shape targets, got '
                             f'{episodes_per_stage!r} ({self.cfg.challenge}).')
        self.episodes_per_stage = episodes_per_stage
        self.episodes = [0] * self.num_envs  # begun per chamber (the curriculum's clock)

    @property
    def chambers(self) -> tuple[Chamber, ...]:
        """The simulated chambers (privileged state, for oracles and tests)."""
        return self._chambers

    def set_target_digits(self, digits: Sequence[int]) -> None:
        """Draw shape targets from these digits from each chamber's next reset on."""
        for sim in self.sims:
            sim.set_target_digits(digits)

    def reset(self, *, seed: int | Sequence[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the chambers: all of them, or those of ``options['reset_mask']``.

        Args:
            seed: None continues each chamber's random stream; an int seeds chamber i with
                ``seed + i``; a sequence gives one seed (or None) per chamber.
            options: ``{'reset_mask': (num_envs,) bool array}`` resets only those chambers.

        Returns:
            The observations of all chambers and the info (see the class docstring).

        Raises:
            ValueError: on a seed list of the wrong length, a bad ``reset_mask``, or a mask
                that leaves chambers out on the first reset.
        """
        seeds = self._seeds(seed)
        mask = np.ones(self.num_envs, bool)
        if options and 'reset_mask' in options:
            mask = options['reset_mask']
            if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ \
                    or mask.shape != (self.num_envs,) or not mask.any():
                raise ValueError(f"options['reset_mask'] must be a bool array of shape "
                                 f'({self.num_envs},) with a True, got {mask!r}.')
        elif options:
            raise ValueError(f"options takes only 'reset_mask', got {sorted(options)}.")
        if not self._started and not mask.all():
            raise ValueError(f"the first reset must reset every chamber, got options['reset_mask']"
                             f' = {mask.tolist()}.')
        outcomes: list[StepOutcome | None] = [None] * self.num_envs
        for i in np.flatnonzero(mask).tolist():
            outcomes[i] = self._reset_chamber(i, seeds[i])
        self._ended[mask] = False
        self._started = True
        return self._observe(), self._info(outcomes)

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        """Apply one action per chamber and grow each one step (see the autoreset modes).

        Raises:
            ValueError: if ``actions`` does not hold one action per chamber.
            RuntimeError: before the first ``reset``, or with ``AutoresetMode.DISABLED`` when
                an ended chamber was not reset.
            growspace_sim.core.errors.CommandError: on an action outside the action space.
        """
        if not self._started:
            raise RuntimeError('call reset() before step().')
        actions = np.asarray(actions)
        if actions.shape != self.action_space.shape:
            raise ValueError(f'actions must have shape {self.action_space.shape} (one action '
                             f'per chamber), got {actions.shape}.')
        mode = self.autoreset_mode
        if mode == AutoresetMode.DISABLED and self._ended.any():
            raise RuntimeError(f'chambers {np.flatnonzero(self._ended).tolist()} ended: reset '
                               f"them (options={{'reset_mask': ...}}) before stepping.")
        outcomes: list[StepOutcome | None] = [None] * self.num_envs
        values = actions if self.continuous else actions.tolist()
        autoreset = self._ended.tolist() if mode == AutoresetMode.NEXT_STEP \
            else [False] * self.num_envs
        for i, sim in enumerate(self.sims):  # Python lists: numpy scalar access costs more
            if autoreset[i]:
                outcomes[i] = self._reset_chamber(i)
            elif self.continuous:
                sim.apply_continuous(values[i])
                outcomes[i] = sim.step()
            else:
                sim.apply_discrete(values[i])
                outcomes[i] = sim.step()
        rewards = np.array([0.0 if reset else o.reward for reset, o in zip(autoreset, outcomes)])
        check_rewards(rewards, self.cfg, max(c.steps for c in self._chambers))
        truncations = np.array([not reset and o.truncated
                                for reset, o in zip(autoreset, outcomes)])
        final: dict[str, Any] = {}
        if mode == AutoresetMode.SAME_STEP and truncations.any():
            final = self._finish(truncations, outcomes)
        if mode != AutoresetMode.SAME_STEP:  # SAME_STEP has reset them already
            self._ended = truncations.copy()
        info = self._info(outcomes)
        info.update(final)
        return self._observe(), rewards, np.zeros(self.num_envs, bool), truncations, info

    def render(self) -> tuple[np.ndarray, ...] | None:
        """Each chamber's RGB image with ``render_mode='rgb_array'``, else None."""
        if self.render_mode != 'rgb_array':
            return None
        return tuple(sim.observe() for sim in self.sims)

    def _finish(self, ended: np.ndarray, outcomes: list[StepOutcome | None]) -> dict[str, Any]:
        """SAME_STEP: keep the ended chambers' last observation and info, then reset them."""
        rows = np.flatnonzero(ended).tolist()
        final_obs = np.full(self.num_envs, None, object)
        last = self._observe()
        for i in rows:
            final_obs[i] = last[i]
        final_info = self._info(outcomes, ended)
        for i in rows:
            outcomes[i] = self._reset_chamber(i)
        return {'final_obs': final_obs, '_final_obs': ended.copy(),
                'final_info': final_info, '_final_info': ended.copy()}

    def _reset_chamber(self, i: int, seed: int | None = None) -> StepOutcome:
        """Reset chamber i; with a curriculum, first give it the digits of its stage."""
        if self.episodes_per_stage is not None:
            stage = min(1 + self.episodes[i] // self.episodes_per_stage,
                        len(digit_data.CURRICULUM_ORDER))
            self.sims[i].set_target_digits(digit_data.CURRICULUM_ORDER[:stage])
        self.episodes[i] += 1
        return self.sims[i].reset(seed=seed)

    def _seeds(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            return [int(seed) + i for i in range(self.num_envs)]
        seeds = list(seed)
        if len(seeds) != self.num_envs:
            raise ValueError(f'seed must be None, an int or {self.num_envs} seeds (one per '
                             f'chamber), got {len(seeds)}.')
        return seeds

    def _observe(self) -> np.ndarray:
        images = np.empty(self.observation_space.shape, np.uint8)
        for i, sim in enumerate(self.sims):
            sim.renderer.render(sim.chamber, out=images[i])
        return (images > 0).view(np.uint8) if self.observation == 'features' else images

    def _info(self, outcomes: list[StepOutcome | None],
              mask: np.ndarray | None = None) -> dict[str, Any]:
        """The batched info of the chambers with an outcome (``mask``: only those); a chamber
        without one reads zeros, as in Gymnasium's vector infos."""
        has = [o is not None for o in outcomes] if mask is None else mask.tolist()
        blank = (0, False, self._zeros, self._zero_counts, (0.0,) * len(LIGHT_KEYS), 0)
        rows = [(c.state.steps, o.success, o.plant_rewards, c.state.branch_counts,
                 (c.state.light.x, c.state.light.z, c.state.light.width, c.state.light.radius),
                 sim.digit or 0) if h else blank
                for sim, c, o, h in zip(self.sims, self.chambers, outcomes, has)]
        step, success, plant_rewards, branch_counts, light, digit = zip(*rows)
        light = np.array(light).T
        has = np.array(has)
        has.flags.writeable = False  # one mask shared by every key
        info: dict[str, Any] = {
            'step': np.array(step, np.int64), 'success': np.array(success),
            'plant_rewards': np.array(plant_rewards),
            'branch_counts': np.array(branch_counts, np.int64),
            'light': {key: light[k] for k, key in enumerate(LIGHT_KEYS)}}
        if self._digits:
            info['digit'] = np.array(digit, np.int64)
        for key in LIGHT_KEYS:
            info['light'][f'_{key}'] = has
        for key in list(info):
            if key != 'light':
                info[f'_{key}'] = has
        info['_light'] = has
        return info


def make_curriculum_vector(num_envs: int = 1, episodes_per_stage: int = 100,
                           **kwargs: Any) -> GrowSpaceVectorEnv:
    """The vector entry point of a digit curriculum (``GrowSpace/Shape-Curriculum-v0``): the
    challenge's chambers (a ``challenge`` keyword of its registration), each with the
    curriculum of ``DigitCurriculum`` (``envs.env.make_curriculum``)."""
    return GrowSpaceVectorEnv(num_envs, episodes_per_stage=episodes_per_stage, **kwargs)
