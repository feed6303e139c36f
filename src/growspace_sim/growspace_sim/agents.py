"""Reference agents: uniform random actions, and an oracle per challenge.

The oracles follow the GrowSpace paper's appendix and read the privileged chamber state (target,
plant nodes) that a learning agent only sees as pixels:
- control / find_plant: while the plant's node nearest to the target and the target share the
  beam, leave the light alone; otherwise steer the widest beam over that node, shifted towards
  the target so mostly photons on the target's side are lit; close to the target, light only the
  reachable photon nearest to it with the narrowest beam;
- fairness: one wide beam over all plants when it can reach them all; otherwise bring one plant
  at a time below the target, so the light alternates between the plants;
- shape: fill the digit bottom-up, keeping the spotlight on the lowest digit pixel that the
  plant does not cover yet and can reach.
They act through the discrete action space, as an agent would.
"""

from __future__ import annotations

from typing import Any, Protocol, Sequence

import gymnasium as gym
import numpy as np

from growspace_sim.core.chamber import Chamber
from growspace_sim.core.light import BEAM_ACTIONS, SPOT_ACTIONS

LEAD = 0.4  # of the beam width: how far ahead of the plant, towards the target, the beam centre is
ARRIVAL = 0.15  # of the chamber width: a plant this close to below the target has arrived
CLOSE_IN = 3.0  # branch lengths: this close to the target, aim single photons at it


class Agent(Protocol):
    def act(self, observation: np.ndarray, env: gym.Env) -> Any:
        """The action for this observation (``env`` gives oracles the privileged state)."""


class RandomAgent:
    """Uniform random actions from the env's action space, seeded for reproducibility."""

    def __init__(self, action_space: gym.Space, seed: int | None = None) -> None:
        self.action_space = action_space
        self.action_space.seed(seed)

    def act(self, observation: np.ndarray, env: gym.Env) -> Any:
        return self.action_space.sample()


class OracleAgent:
    """The per-challenge oracle described in the module docstring (discrete actions only)."""

    def __init__(self) -> None:
        self._focus = 0  # fairness: the plant the beam is working on

    def act(self, observation: np.ndarray, env: gym.Env) -> int:
        base = env.unwrapped
        if getattr(base, 'continuous', False):
            raise ValueError('OracleAgent acts through discrete actions; use a discrete env id.')
        chamber: Chamber = base.chamber
        if chamber.light.spot:
            return _shape_action(chamber)
        cfg = chamber.cfg
        leads = _leading_nodes(chamber)
        widest = cfg.width_m(cfg.light_width_max)  # more lit photons, faster growth
        margin = LEAD * widest
        if cfg.plant_count > 1:
            span = leads.real.max() - leads.real.min() + 2.0 * margin
            if span <= widest:  # one beam can feed every plant
                return _beam_action(chamber, 0.5 * (leads.real.max() + leads.real.min()), widest)
            lead = leads[self._fairness_focus(chamber, leads)]
        else:
            lead = leads[0]
            near = abs(lead - chamber.target) < CLOSE_IN * cfg.branch_length_m
            photon = _photon_nearest_target(chamber) if near else None
            if photon is not None and abs(photon - chamber.target) < abs(lead - chamber.target):
                # Close in: light only the reachable photon that lies nearest to the target.
                return _beam_action(chamber, photon.real, cfg.width_m(cfg.light_width_min))
            half = 0.5 * chamber.light.width
            if abs(chamber.target.real - chamber.light.x) <= half \
                    and abs(lead.real - chamber.light.x) <= half:
                # Lead and target share the beam: leave it. Moving or widening it would feed
                # side branches, which take growth slots (max_branching) from the lead.
                return BEAM_ACTIONS.index('stay')
        goal = lead.real + float(np.clip(chamber.target.real - lead.real, -margin, margin))
        return _beam_action(chamber, goal, widest)

    def _fairness_focus(self, chamber: Chamber, leads: np.ndarray) -> int:
        """Bring one plant at a time below the target, then the next one.

        Moving the beam across the chamber costs many steps, so it stays with a plant until that
        plant has arrived instead of chasing the lowest reward at every step.
        """
        arrived = np.abs(leads.real - chamber.target.real) < ARRIVAL * chamber.cfg.chamber_width
        if chamber.steps == 0 or arrived[self._focus]:
            distance = np.abs(leads.real - chamber.light.x)
            self._focus = int(np.argmin(np.where(arrived, np.inf, distance)))
        return self._focus


def _leading_nodes(chamber: Chamber) -> np.ndarray:
    """Per plant, its node nearest to the target (complex, m)."""
    nodes = chamber.pos[:chamber.n_nodes]
    owner = chamber.plant[:chamber.n_nodes]
    distance = np.abs(nodes - chamber.target)
    return np.array([nodes[owner == p][np.argmin(distance[owner == p])]
                     for p in range(chamber.cfg.plant_count)])


def _reachable_photons(chamber: Chamber) -> np.ndarray:
    """Unshaded photons within the radius of influence of some node (complex, m)."""
    photons = chamber.photons[~chamber.shaded]
    nodes = chamber.pos[:chamber.n_nodes]
    if photons.size == 0:
        return photons
    gap = np.abs(photons[:, None] - nodes).min(axis=1)
    return photons[gap < chamber.cfg.width_m(chamber.cfg.radius_of_influence)]


def _photon_nearest_target(chamber: Chamber) -> complex | None:
    photons = _reachable_photons(chamber)
    if photons.size == 0:
        return None
    return complex(photons[np.argmin(np.abs(photons - chamber.target))])


def _beam_action(chamber: Chamber, centre: float, width: float) -> int:
    """The discrete action that brings the beam closest to (centre, width): move, then resize."""
    step, light = chamber.cfg.light_step_m, chamber.light
    move = _towards(centre - light.x, step, 'left', 'right')
    if move == 'stay':
        move = _towards(width - light.width, step, 'narrower', 'wider')
    return BEAM_ACTIONS.index(move)


def _shape_action(chamber: Chamber) -> int:
    """Spot the lowest reachable photon in an uncovered digit pixel (fill bottom-up).

    Without one, spot the reachable photon nearest to an uncovered digit pixel.
    """
    cfg, light = chamber.cfg, chamber.light
    photons = _reachable_photons(chamber)
    rows, cols = np.nonzero(chamber.target_mask & ~chamber.occupancy)
    if photons.size == 0 or rows.size == 0:
        return SPOT_ACTIONS.index('stay')
    pixel = cfg.chamber_width / cfg.resolution
    wanted = (cols + 0.5) * pixel + 1j * (cfg.chamber_height - (rows + 0.5) * pixel)
    gap = np.abs(photons[:, None] - wanted).min(axis=1)
    inside = gap < 0.75 * pixel
    if inside.any():
        goal = photons[inside][np.argmin(photons[inside].imag)]
    else:
        goal = photons[np.argmin(gap)]
    step = cfg.light_step_m
    dx, dz = goal.real - light.x, goal.imag - light.z
    if abs(dx) >= abs(dz):
        return SPOT_ACTIONS.index(_towards(dx, step, 'left', 'right'))
    return SPOT_ACTIONS.index(_towards(dz, step, 'down', 'up'))


def _towards(error: float, step: float, negative: str, positive: str) -> str:
    if error > 0.5 * step:
        return positive
    if error < -0.5 * step:
        return negative
    return 'stay'


def run_episode(env: gym.Env, agent: Agent, seed: int) -> tuple[float, dict]:
    """One seeded episode; returns the undiscounted return and the last info."""
    observation, info = env.reset(seed=seed)
    total, done = 0.0, False
    while not done:
        observation, reward, terminated, truncated, info = env.step(
            agent.act(observation, env))
        total += float(reward)
        done = terminated or truncated
    return total, info


def play_episodes(env: gym.Env, agent: Agent,
                  seeds: Sequence[int]) -> tuple[np.ndarray, list[dict]]:
    """Seeded episodes; returns per-step rewards and each episode's last info.

    Args:
        env: The environment, reset with each seed in turn.
        agent: Acts on every observation.
        seeds: One episode per seed.

    Returns:
        Rewards, shape (episodes, steps) float64, zero-padded past an early termination, and
        the last ``info`` of every episode.
    """
    rows, infos = [], []
    for seed in seeds:
        observation, info = env.reset(seed=seed)
        rewards, done = [], False
        while not done:
            observation, reward, terminated, truncated, info = env.step(
                agent.act(observation, env))
            rewards.append(float(reward))
            done = terminated or truncated
        rows.append(rewards)
        infos.append(info)
    width = max((len(r) for r in rows), default=0)
    padded = np.array([r + [0.0] * (width - len(r)) for r in rows], np.float64)
    return padded.reshape(len(rows), width), infos
