"""PPO's rollout buffer with its minibatches cut on the training device.

Stable-Baselines3's ``RolloutBuffer.get`` indexes its numpy arrays once per minibatch and
copies each minibatch to the device: in the case studies (2,048 steps per update, minibatches
of 64, 4 epochs) that is 128 host-side gathers and 128 small host-to-device copies per update.
``DeviceRolloutBuffer`` copies the flattened rollout to the device once per update and gathers
each minibatch there. It draws the same permutation (``np.random.permutation``, so the same
global numpy stream) and holds the same values (observations stay uint8, as SB3 stores them),
so every minibatch, and so the training, is the same; tests/sim/test_learn.py compares the two
buffers' minibatches element by element.
"""

from __future__ import annotations

from collections.abc import Generator

import numpy as np
import torch as th
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.type_aliases import RolloutBufferSamples

_FIELDS = ('observations', 'actions', 'values', 'log_probs', 'advantages', 'returns')


class DeviceRolloutBuffer(RolloutBuffer):
    """``RolloutBuffer`` whose ``get`` moves the rollout to ``device`` once per update."""

    def reset(self) -> None:
        super().reset()
        self._device_data: dict[str, th.Tensor] = {}

    def get(self, batch_size: int | None = None
            ) -> Generator[RolloutBufferSamples, None, None]:
        """Minibatches of the flattened rollout in a random order, as SB3's ``get``.

        Raises:
            RuntimeError: the buffer is not full yet.
        """
        if not self.full:
            raise RuntimeError('get() before the rollout filled the buffer.')
        total = self.buffer_size * self.n_envs
        indices = np.random.permutation(total)
        if not self.generator_ready:
            for name in _FIELDS:
                self.__dict__[name] = self.swap_and_flatten(self.__dict__[name])
            self._device_data = {name: th.as_tensor(self.__dict__[name], device=self.device)
                                 for name in _FIELDS}
            # SB3 casts actions to float32 per minibatch (MultiBinary spaces aside)
            self._device_data['actions'] = self._device_data['actions'].float()
            self.generator_ready = True
        batch_size = batch_size or total
        order = th.as_tensor(indices, device=self.device)
        for start in range(0, total, batch_size):
            yield self._gather(order[start:start + batch_size])

    def _gather(self, rows: th.Tensor) -> RolloutBufferSamples:
        data = self._device_data
        return RolloutBufferSamples(
            observations=data['observations'][rows], actions=data['actions'][rows],
            old_values=data['values'][rows].flatten(),
            old_log_prob=data['log_probs'][rows].flatten(),
            advantages=data['advantages'][rows].flatten(),
            returns=data['returns'][rows].flatten())
