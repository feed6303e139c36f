"""Stable-Baselines3 on the native vector env: an SB3 ``VecEnv`` over ``GrowSpaceVectorEnv``.

SB3 trains on its own ``VecEnv`` type, not on Gymnasium's ``VectorEnv``; its documentation
adapts batched simulators (EnvPool, Procgen) the same way. ``NativeVecEnv`` steps N chambers in
one call and gives SB3 what ``DummyVecEnv`` over N ``GrowSpaceEnv`` gives for the same seeds:
the same observations, rewards and dones; at an episode's end ``terminal_observation`` and
``TimeLimit.truncated`` in that chamber's info and the next episode's first observation in its
place (tests/sim/test_learn.py compares the two step by step). Wrap it in ``VecMonitor`` for the
episode returns that ``Monitor`` gives single envs (``train.make_env(..., vec='native')`` does).

Each chamber's info has the single env's keys except ``tips`` (the vector env does not batch
them; read ``venv.chambers[i].tip_positions()``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
from gymnasium.vector import AutoresetMode
import numpy as np
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from growspace_sim.envs.vector import GrowSpaceVectorEnv, LIGHT_KEYS


class NativeVecEnv(VecEnv):
    """``num_envs`` chambers of ``env_id`` as one Stable-Baselines3 ``VecEnv``.

    Args:
        env_id: A GrowSpace id, e.g. ``GrowSpace/Control-Easy-v0``.
        num_envs: Chambers stepped together.
        **env_kwargs: As for ``gymnasium.make`` of that id (``continuous``, ``observation``,
            ``SimConfig`` overrides ...).

    Raises:
        ValueError: ``env_id`` has no native vector env, or a keyword is invalid.
    """

    def __init__(self, env_id: str, num_envs: int, **env_kwargs: Any) -> None:
        venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode='vector_entry_point',
                            autoreset_mode=AutoresetMode.SAME_STEP, **env_kwargs)
        if not isinstance(venv.unwrapped, GrowSpaceVectorEnv):
            raise ValueError(f'{env_id} has no GrowSpace vector env (got {type(venv).__name__}).')
        self.venv: GrowSpaceVectorEnv = venv.unwrapped
        self._actions: np.ndarray | None = None
        super().__init__(self.venv.num_envs, self.venv.single_observation_space,
                         self.venv.single_action_space)

    def reset(self) -> np.ndarray:
        """Reset every chamber with the seeds given to ``seed()`` (then forgotten), else
        continuing each chamber's random stream, as ``DummyVecEnv`` does.

        Raises:
            ValueError: options were set: GrowSpace resets take none.
        """
        if any(self._options):
            raise ValueError(f'GrowSpace resets take no options, got {self._options}.')
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        obs, info = self.venv.reset(seed=seeds)
        self.reset_infos = self._unbatch(info, range(self.num_envs))
        self._reset_seeds()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError('step_wait() without step_async(actions).')
        actions, self._actions = self._actions, None
        obs, rewards, terminated, truncated, info = self.venv.step(actions)
        dones = terminated | truncated
        infos = self._unbatch(info, range(self.num_envs))
        ended = np.flatnonzero(dones).tolist()
        if ended:  # SAME_STEP: these chambers were reset; their last step is in final_*
            for i, final in zip(ended, self._unbatch(info['final_info'], ended)):
                final['terminal_observation'] = info['final_obs'][i]
                infos[i] = final
        for i, info_i in enumerate(infos):
            info_i['TimeLimit.truncated'] = bool(truncated[i] and not terminated[i])
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """An attribute of the vector env, once per index (the chambers share it)."""
        value = getattr(self.venv, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the vector env: for every chamber at once only.

        Raises:
            ValueError: ``indices`` names only some of the chambers.
        """
        if sorted(self._get_indices(indices)) != list(range(self.num_envs)):
            raise ValueError(f'{attr_name}: the chambers share one vector env; set it for all '
                             f'{self.num_envs} of them (indices=None), not {indices!r}.')
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        """Call a method of each chamber's ``Simulation`` (e.g. ``observe``)."""
        return [getattr(self.venv.sims[i], method_name)(*method_args, **method_kwargs)
                for i in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper],
                       indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]  # no per-chamber wrappers

    def get_images(self) -> Sequence[np.ndarray | None]:
        images = self.venv.render()
        return list(images) if images is not None else [None] * self.num_envs

    def _unbatch(self, info: dict[str, Any], rows: Sequence[int]) -> list[dict[str, Any]]:
        """Per-chamber info dicts (the single env's keys but ``tips``) from the batched one."""
        light = info['light']
        digit = info.get('digit')
        infos = []
        for i in rows:
            row = {'step': int(info['step'][i]), 'branch_counts': info['branch_counts'][i],
                   'plant_rewards': info['plant_rewards'][i],
                   'light': {key: float(light[key][i]) for key in LIGHT_KEYS},
                   'success': bool(info['success'][i])}
            if digit is not None:
                row['digit'] = int(digit[i])
            infos.append(row)
        return infos
