"""The messages a chamber publishes during a seeded episode, built in process.

For the view's benchmark, its screenshot script and its tests: the same ``convert`` functions
the node uses, in the node's order per tick (config on reset, plant state, light state, step
result), without a ROS graph.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from growspace_sim.core.config import SimConfig
from growspace_sim.ros import convert
from growspace_sim.ros import types
from growspace_sim.ros.interface import config_json
from growspace_sim.simulation import Simulation

PERIOD_NS = 20_000_000  # 50 Hz


def episode_messages(cfg: SimConfig, seed: int, steps: int | None = None, *,
                     oracle: bool = True, frame_id: str = 'chamber',
                     ) -> Iterator[tuple[str, Any]]:
    """(topic, rosbags message) pairs of one episode, reset first.

    Args:
        cfg: the chamber's configuration.
        seed: the episode's seed (sent in ``chamber/config``).
        steps: ticks after the reset; the episode's length when None.
        oracle: steer with the challenge's oracle (a plant worth looking at), else stay.
        frame_id: the chamber frame of the headers.

    Yields:
        ``('chamber/config', String)`` once, then per tick ``plant/state``, ``light/state``
        and ``step_result``.
    """
    sim = Simulation(cfg)
    outcome = sim.reset(seed=seed)
    agent = cfg.task.oracle() if oracle and cfg.task.oracle is not None else None
    stamp = PERIOD_NS
    payload = config_json(cfg, seed, frame_id=frame_id, digit=sim.digit, reset_id=0)
    yield 'chamber/config', types.new(types.STRING, data=payload)
    total = cfg.episode_length if steps is None else min(steps, cfg.episode_length)
    for step in range(total + 1):
        if step:
            if agent is not None:
                sim.apply_discrete(agent.act(sim.chamber))
            outcome = sim.step()
            stamp += PERIOD_NS
        chamber = sim.chamber
        yield 'plant/state', convert.plant_state_msg(chamber, step, stamp, frame_id)
        yield 'light/state', convert.light_msg(chamber.light, step, stamp, frame_id)
        yield 'step_result', convert.step_result_msg(
            outcome, step_id=step, reset_id=0, step=chamber.steps, stamp_ns=stamp,
            frame_id=frame_id)


def feed(scene: Any, topic: str, msg: Any) -> Any:
    """Hand one message to a ``Scene``; returns the frame a ``step_result`` gives, else None."""
    if topic == 'chamber/config':
        scene.on_config(msg.data)
    elif topic == 'plant/state':
        scene.on_plant(msg)
    elif topic == 'light/state':
        scene.on_light(msg)
    elif topic == 'step_result':
        return scene.on_result(msg)
    return None


def readme_frame(scene: Any, step: int = 30) -> Any:
    """The frame the README's pictures show: control easy, seed 0, the oracle, ``step``."""
    frame = None
    for topic, msg in episode_messages(SimConfig(), 0, step):
        frame = feed(scene, topic, msg) or frame
    return frame
