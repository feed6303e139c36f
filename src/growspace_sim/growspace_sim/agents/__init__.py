"""Agents and their evaluation: the random agent and the challenges' oracles (``reference``),
and seeded episodes played by any of them (``evaluate``)."""

from growspace_sim.agents.reference import (
    Agent, OracleAgent, play_episodes, RandomAgent, run_episode)

__all__ = ['Agent', 'OracleAgent', 'RandomAgent', 'play_episodes', 'run_episode']
