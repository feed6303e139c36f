"""Rainbow DQN (Hessel et al. 2018) on top of Stable-Baselines3's DQN.

All six components of the paper's Rainbow, each a small addition to SB3's DQN:

- double Q-learning: the online network picks the next action, the target network rates it;
- prioritized replay (proportional, alpha 0.5, beta annealed 0.4 -> 1), here without a sum
  tree: sampling normalises the priorities of the filled buffer (O(N) per batch, fine for the
  buffer sizes a CPU run uses);
- dueling value and advantage streams;
- multi-step returns: SB3's own ``NStepReplayBuffer`` code (n = 3);
- distributional C51 head (51 atoms on [v_min, v_max], cross-entropy to the projected target);
- noisy linear layers (factorised Gaussian, sigma0 0.5) replace epsilon-greedy exploration.

Why on SB3 and not tianshou's RainbowDQN or sb3-contrib: one library, so that checkpoints,
logging, callbacks, vectorised envs and ``load``/``predict`` are the same for every baseline;
sb3-contrib only has QR-DQN (distributional, none of the other five).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np
import torch
import torch.nn.functional as F
from stable_baselines3 import DQN
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import ReplayBufferSamples
from stable_baselines3.dqn.policies import DQNPolicy, QNetwork
from torch import nn


class NoisyLinear(nn.Module):
    """Factorised-Gaussian noisy linear layer (Fortunato et al. 2018)."""

    def __init__(self, in_features: int, out_features: int, sigma0: float = 0.5) -> None:
        super().__init__()
        self.in_features, self.out_features = in_features, out_features
        bound = 1.0 / math.sqrt(in_features)
        weight = torch.empty(out_features, in_features).uniform_(-bound, bound)
        self.weight_mu = nn.Parameter(weight)
        self.weight_sigma = nn.Parameter(torch.full((out_features, in_features), sigma0 * bound))
        self.bias_mu = nn.Parameter(torch.empty(out_features).uniform_(-bound, bound))
        self.bias_sigma = nn.Parameter(torch.full((out_features,), sigma0 * bound))
        self.register_buffer('eps_in', torch.zeros(in_features))
        self.register_buffer('eps_out', torch.zeros(out_features))
        self.noisy = True  # off: the mean weights (greedy evaluation)
        self.reset_noise()

    @staticmethod
    def _scaled(size: int, device: torch.device) -> torch.Tensor:
        x = torch.randn(size, device=device)
        return x.sign() * x.abs().sqrt()

    def reset_noise(self) -> None:
        self.eps_in.copy_(self._scaled(self.in_features, self.eps_in.device))
        self.eps_out.copy_(self._scaled(self.out_features, self.eps_out.device))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.noisy:
            return F.linear(x, self.weight_mu, self.bias_mu)
        weight = self.weight_mu + self.weight_sigma * torch.outer(self.eps_out, self.eps_in)
        return F.linear(x, weight, self.bias_mu + self.bias_sigma * self.eps_out)


class RainbowQNetwork(QNetwork):
    """Features -> dueling noisy heads -> a categorical return distribution per action."""

    def __init__(self, *args: Any, n_atoms: int = 51, v_min: float = 0.0, v_max: float = 40.0,
                 **kwargs: Any) -> None:
        kwargs['net_arch'] = []
        super().__init__(*args, **kwargs)
        del self.q_net  # replaced by the dueling distributional heads
        self.n_atoms, self.v_min, self.v_max = n_atoms, v_min, v_max
        n_actions = int(self.action_space.n)
        self.value = NoisyLinear(self.features_dim, n_atoms)
        self.advantage = NoisyLinear(self.features_dim, n_actions * n_atoms)
        self.register_buffer('support', torch.linspace(v_min, v_max, n_atoms))

    def dist(self, obs: torch.Tensor, log: bool = False) -> torch.Tensor:
        """(batch, actions, atoms) probabilities (or log-probabilities)."""
        features = self.extract_features(obs, self.features_extractor)
        value = self.value(features).view(-1, 1, self.n_atoms)
        advantage = self.advantage(features).view(-1, int(self.action_space.n), self.n_atoms)
        logits = value + advantage - advantage.mean(dim=1, keepdim=True)
        return F.log_softmax(logits, dim=2) if log else F.softmax(logits, dim=2)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return (self.dist(obs) * self.support).sum(dim=2)

    def noisy_layers(self) -> list[NoisyLinear]:
        return [self.value, self.advantage]

    def reset_noise(self) -> None:
        for layer in self.noisy_layers():
            layer.reset_noise()

    def set_noisy(self, noisy: bool) -> None:
        for layer in self.noisy_layers():
            layer.noisy = noisy

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(n_atoms=self.n_atoms, v_min=self.v_min, v_max=self.v_max)
        return data


class RainbowPolicy(DQNPolicy):
    """SB3's DQN CNN policy with the Rainbow Q-network (atoms and support in policy_kwargs)."""

    def __init__(self, *args: Any, n_atoms: int = 51, v_min: float = 0.0, v_max: float = 40.0,
                 **kwargs: Any) -> None:
        self._dist_kwargs = dict(n_atoms=n_atoms, v_min=v_min, v_max=v_max)
        super().__init__(*args, **kwargs)

    def make_q_net(self) -> RainbowQNetwork:
        net_args = self._update_features_extractor(self.net_args, features_extractor=None)
        return RainbowQNetwork(**net_args, **self._dist_kwargs).to(self.device)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(self._dist_kwargs)
        return data


class PrioritizedNStepReplayBuffer(NStepReplayBuffer):
    """SB3's n-step buffer with proportional prioritized sampling (Schaul et al. 2016)."""

    def __init__(self, *args: Any, alpha: float = 0.5, beta: float = 0.4,
                 priority_eps: float = 1e-6, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.alpha, self.beta, self.priority_eps = alpha, beta, priority_eps
        self.priorities = np.zeros((self.buffer_size, self.n_envs), np.float64)
        self.max_priority = 1.0
        self.last_indices: tuple[np.ndarray, np.ndarray] | None = None
        self.last_weights: np.ndarray | None = None

    def add(self, *args: Any, **kwargs: Any) -> None:
        self.priorities[self.pos] = self.max_priority  # new transitions: the highest priority
        super().add(*args, **kwargs)

    def sample(self, batch_size: int, env: Any = None) -> ReplayBufferSamples:
        size = self.buffer_size if self.full else self.pos
        p = self.priorities[:size].ravel() ** self.alpha
        p /= p.sum()
        flat = np.random.choice(p.size, size=batch_size, p=p)
        batch_inds, env_inds = np.divmod(flat, self.n_envs)
        weights = (p.size * p[flat]) ** -self.beta
        self.last_indices, self.last_weights = (batch_inds, env_inds), weights / weights.max()
        return self._n_step_samples(batch_inds, env_inds, env)

    def update_priorities(self, errors: np.ndarray) -> None:
        """New priorities for the last sampled batch (its per-sample losses)."""
        priorities = np.abs(errors) + self.priority_eps
        self.priorities[self.last_indices] = priorities
        self.max_priority = max(self.max_priority, float(priorities.max()))

    def _n_step_samples(self, batch_inds: np.ndarray, env_indices: np.ndarray,
                        env: Any = None) -> ReplayBufferSamples:
        # NStepReplayBuffer._get_samples draws env indices itself; this is the same computation
        # with the prioritized (index, env) pairs.
        last_valid = self.pos - 1
        saved = self.timeouts[last_valid].copy()
        self.timeouts[last_valid] = np.logical_or(saved, np.logical_not(self.dones[last_valid]))
        indices = (batch_inds[:, None] + np.arange(self.n_steps)[None]) % self.buffer_size
        rewards = self._normalize_reward(self.rewards[indices, env_indices[:, None]], env)
        ended = np.logical_or(self.dones[indices, env_indices[:, None]],
                              self.timeouts[indices, env_indices[:, None]])
        end = np.where(ended.any(axis=1), ended.argmax(axis=1), self.n_steps - 1)
        mask = np.arange(self.n_steps)[None] <= end[:, None]
        target_discounts = self.gamma ** mask.sum(axis=1, keepdims=True).astype(np.float32)
        returns = (rewards * self.gamma ** np.arange(self.n_steps, dtype=np.float32)[None]
                   * mask).sum(axis=1, keepdims=True)
        last = (batch_inds + end) % self.buffer_size
        next_obs = self._normalize_obs(self.next_observations[last, env_indices], env)
        dones = (self.dones[last, env_indices] * (1.0 - self.timeouts[last, env_indices]))
        self.timeouts[last_valid] = saved
        obs = self._normalize_obs(self.observations[batch_inds, env_indices], env)
        return ReplayBufferSamples(
            observations=self.to_torch(obs),
            actions=self.to_torch(self.actions[batch_inds, env_indices]),
            next_observations=self.to_torch(next_obs),
            dones=self.to_torch(dones[:, None].astype(np.float32)),
            rewards=self.to_torch(returns), discounts=self.to_torch(target_discounts))


class Rainbow(DQN):
    """DQN + the five other Rainbow components (see the module docstring).

    Args beyond DQN's: ``alpha`` and ``beta0`` (prioritized replay); the atoms and the support
    go in ``policy_kwargs`` (``n_atoms``, ``v_min``, ``v_max``): GrowSpace rewards lie in [0, 1]
    and episodes last 50 steps, so discounted returns lie in [0, 40].
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {'RainbowPolicy': RainbowPolicy}

    def __init__(self, policy: Any, env: Any, n_steps: int = 3, alpha: float = 0.5,
                 beta0: float = 0.4, adam_eps: float = 1.5e-4, **kwargs: Any) -> None:
        self.alpha, self.beta0 = alpha, beta0
        kwargs.setdefault('replay_buffer_class', PrioritizedNStepReplayBuffer)
        buffer_kwargs = dict(kwargs.pop('replay_buffer_kwargs', None) or {})
        buffer_kwargs.update(n_steps=n_steps, gamma=kwargs.get('gamma', 0.99), alpha=alpha,
                             beta=beta0)
        policy_kwargs = dict(kwargs.pop('policy_kwargs', None) or {})
        policy_kwargs.setdefault('optimizer_kwargs', {'eps': adam_eps})
        # Noisy nets explore; no epsilon-greedy. No Huber clipping of the distributional loss.
        kwargs.setdefault('exploration_initial_eps', 0.0)
        kwargs.setdefault('exploration_final_eps', 0.0)
        super().__init__(policy, env, replay_buffer_kwargs=buffer_kwargs,
                         policy_kwargs=policy_kwargs, **kwargs)
        self.rainbow_n_steps = n_steps

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        buffer: PrioritizedNStepReplayBuffer = self.replay_buffer  # type: ignore[assignment]
        buffer.beta = self.beta0 + (1.0 - self.beta0) * (1.0 - self._current_progress_remaining)
        q_net, target = self.q_net, self.q_net_target
        q_net.set_noisy(True)
        support, n_atoms = q_net.support, q_net.n_atoms
        delta = (q_net.v_max - q_net.v_min) / (n_atoms - 1)
        losses = []
        for _ in range(gradient_steps):
            q_net.reset_noise()
            target.reset_noise()
            data = buffer.sample(batch_size, env=self._vec_normalize_env)
            weights = torch.as_tensor(buffer.last_weights, dtype=torch.float32, device=self.device)
            rows = torch.arange(batch_size, device=self.device)
            with torch.no_grad():
                next_actions = q_net(data.next_observations).argmax(dim=1)  # double Q
                next_probs = target.dist(data.next_observations)[rows, next_actions]
                tz = (data.rewards + (1 - data.dones) * data.discounts * support[None]).clamp(
                    q_net.v_min, q_net.v_max)
                b = (tz - q_net.v_min) / delta
                low, up = b.floor().long(), b.ceil().long()
                low[(up > 0) & (low == up)] -= 1
                up[(low < n_atoms - 1) & (low == up)] += 1
                projected = torch.zeros_like(next_probs)
                offset = (rows * n_atoms)[:, None]
                projected.view(-1).index_add_(0, (low + offset).view(-1),
                                              (next_probs * (up.float() - b)).view(-1))
                projected.view(-1).index_add_(0, (up + offset).view(-1),
                                              (next_probs * (b - low.float())).view(-1))
            log_probs = q_net.dist(data.observations, log=True)[rows, data.actions.long().view(-1)]
            sample_loss = -(projected * log_probs).sum(dim=1)
            loss = (weights * sample_loss).mean()
            losses.append(loss.item())
            self.policy.optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
            buffer.update_priorities(sample_loss.detach().cpu().numpy())
        self._n_updates += gradient_steps
        self.logger.record('train/n_updates', self._n_updates, exclude='tensorboard')
        self.logger.record('train/loss', float(np.mean(losses)))
        self.logger.record('train/per_beta', buffer.beta)

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = False) -> tuple[np.ndarray, Any]:
        """Noisy weights while exploring, their means for a deterministic (greedy) action."""
        self.q_net.set_noisy(not deterministic)
        return self.policy.predict(observation, state, episode_start, deterministic)
