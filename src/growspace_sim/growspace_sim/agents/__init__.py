"""Agents and their evaluation: the random agent and the challenges' oracles (``reference``),
and the one episode loop that plays any of them on seeded episodes (``evaluation``)."""

from growspace_sim.agents.evaluation import Episodes, evaluate, make_agent, play_episodes
from growspace_sim.agents.reference import Agent, OracleAgent, RandomAgent

__all__ = ['Agent', 'Episodes', 'OracleAgent', 'RandomAgent', 'evaluate', 'make_agent',
           'play_episodes']
