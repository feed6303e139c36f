"""Where a restarted ``gantry_node`` goes on: the last episode of its own recording.

A gantry cannot re-simulate a plant; what it needs to continue an episode is what it answered:
the episode's ``reset_id`` and seed (its light layout and target), the highest ``step_id`` it
answered (the lockstep rule then refuses a late duplicate), its step count, and the light the
machine last reported reaching. ``resume_path`` (a parameter, as on ``sim_node``) names the
recording; read before the node opens its own next file there.

What the node then does (``node.py``): it keeps the episode's ``reset_id`` and step count, so a
resumed ``growspace-rig`` run attached to it gets its answers; nothing moves at start-up. The
machine position is not established after a restart (rule 1d of ``safety.py``), so the first
relative action is applied to the recorded light and sent as an ABSOLUTE move (safe to repeat:
the design's "place the light again"), which re-establishes the position once reached; also
after a person homed the machine (homing puts the light elsewhere than the episode left it).
Where GRBL is in alarm, that command is refused like any other until a person unlocks or homes
it (``growspace-rig`` then prints WAITING FOR A PERSON and retries).

A step that failed mid-episode (an unplug, an alarm, a camera gone) is redone the same way
(``StepBase``). Not covered: a position lost BETWEEN two steps and re-established by homing:
the next relative action starts from where homing left the machine (rule 1d).

Why the step in progress is never lost nor done twice: ``record.py`` writes each step's answer
to the recording and pushes it to the OS before it is published, so a step the runner saw
answered is in the recording; a step the node was killed in (no answer recorded) has a step_id
above the recorded ones, so the runner's resend of it is accepted and done once.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any

from growspace_sim.core.config import SimConfig


class ResumeError(ValueError):
    """``resume_path`` cannot be continued; the message names the path and why."""


@dataclasses.dataclass(frozen=True)
class GantryResume:
    """The last episode of a gantry recording, to go on with.

    Attributes:
        cfg: The episode's configuration (challenge, setting, ...).
        seed: Its seed (its light layout and target).
        reset_id: Its reset_id: the resumed node answers with it.
        last_step_id: The highest step_id answered in it (refused ones included).
        steps: Steps the node had counted in it (the last answer's ``step``).
        light: (x, z, width, radius) the machine last reported reaching [m], or None.
        over: The episode had ended (truncated or terminated).
    """

    cfg: SimConfig
    seed: int
    reset_id: int
    last_step_id: int
    steps: int
    light: tuple[float, float, float, float] | None
    over: bool


def load(path: str) -> GantryResume | None:
    """Read ``resume_path`` (a split recording's directory is repaired first).

    Returns:
        The resume point; None when the recording holds no episode (nothing to continue).

    Raises:
        ResumeError: It cannot be read, or its last episode has no recorded config or seed.
    """
    from growspace_sim.recording import is_split_recording, RecordingError, repair
    from growspace_sim.replay import Bag, read_episodes, ReplayError

    if not os.path.exists(path):
        raise ResumeError(f'resume_path = {path!r} does not exist')
    try:
        if is_split_recording(path):
            repair(path)
        with Bag(path) as bag:
            episodes = read_episodes(bag)
            if not episodes:
                return None
            last = episodes[-1]
            light_msg = next((s.outputs['light/state'] for s in reversed(last.steps)
                              if 'light/state' in s.outputs), None)
            reached = None if light_msg is None else light_msg.decode()
    except (ReplayError, RecordingError, OSError) as e:
        raise ResumeError(f'resume_path = {path!r} cannot be read: {e}') from None
    if last.config is None or last.seed is None:
        raise ResumeError(f'resume_path = {path!r}: its last episode (reset_id '
                          f'{last.reset_id}) has no recorded config or seed')
    results = [s.result for s in last.steps] + list(last.rejected)
    light = None if reached is None else (float(reached.x), float(reached.z),
                                          float(reached.width), float(reached.radius))
    return GantryResume(last.config, int(last.seed), last.reset_id,
                        max(int(r.step_id) for r in results),
                        max(int(r.step) for r in results), light, last.done)


Light = tuple[float, float, float, float]  # x, z, width, radius [m]


class StepBase:
    """The light a lockstep step's relative action applies to, where not the reached one.

    The agent's action ``a_t`` moves the light from where step ``t-1`` left it. Two cases
    where the machine is not there, and the action is applied to that light instead (the
    target then sent as an absolute move, safe to repeat):

    - resumed (``resume``): the light the recording's last step reached; the node also lets
      this one action through while the position is not established (``bypass``);
    - a step that failed after moving (a fault in its growth period, no photo): the agent redoes
      it with the same action, which must not add to the failed move (the machine may stand at
      the failed step's target, or at home after a person homed it).
    """

    def __init__(self) -> None:
        self.answered: Light | None = None  # the light the last answered step reached
        self.base: Light | None = None  # the next relative action applies to this one
        self.bypass = False

    def resume(self, light: Light | None) -> None:
        self.answered = self.base = light
        self.bypass = light is not None

    def answered_at(self, light_msg: Any) -> None:
        """A step (or reset) was answered with this reached light (a LightCommand)."""
        self.answered = (float(light_msg.x), float(light_msg.z), float(light_msg.width),
                         float(light_msg.radius))
        self.base = None

    def failed(self) -> None:
        """The step in progress failed: its redo starts where the last answered one ended."""
        self.base = self.answered

    def take(self) -> Light | None:
        """The base for the command being computed now (then none: it is used once)."""
        base, self.base, self.bypass = self.base, None, False
        return base
