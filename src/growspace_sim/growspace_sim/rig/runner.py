"""The experiment runner: a policy drives a lockstep chamber for N episodes, and resumes.

The loop (``Runner.run``) is written once against ``RigChamber``: ``reset(reset_id, seed)`` and
``step(reset_id, step_id, action)`` answered by the chamber's ``step_result`` and image; the
chambers (``rig.chambers``) talk over the bridge's ``ChamberLink`` (the topics a Gymnasium
agent uses):

- ``SimChamber``: the runner starts ``sim_node`` (lockstep) recording into the run directory,
  split by size and duration; on resume it starts it again with ``resume_path`` on that
  recording, so the simulator continues the same episode bit for bit;
- ``AttachedChamber``: a lockstep chamber someone started (``sim_node``, or ``gantry_node`` with
  ``camera_node``), attached by namespace.

Nothing twice, nothing lost: before a step is sent its intent is journaled (fsynced), after its
answer its completion. On resume the recording is what the chamber did, the journal what the
runner knows; ``reconcile`` makes them agree before the next step:

- a step the chamber answered (in its recording) but the journal has only as intent is
  adopted from the recording, never sent again;
- steps the journal holds but the recording lost (a chamber killed before its last chunk
  reached the disk) are re-simulated on the resumed simulator with their journaled actions and
  checked against the journaled rewards bit for bit, which records them (once);
- a reset the chamber answered but the journal lacks is adopted the same way.

Each step gets a new step_id (never one sent before), so the chamber's lockstep rule refuses any
late duplicate; the one exception, a step in progress at the crash resent to an attached
chamber, keeps its own id for that very reason. Where the chamber refuses a step (an attached
gantry in alarm or e-stop: a person must clear it), the runner says so, waits
``retry_period_s`` and tries again with a new step_id; a reset refused as not ready (the same,
or a gantry still starting) is sent again after that wait with its own reset_id. Hook for the
rig's growth period and photoperiod (``gantry_node`` ``growth_s``, built separately): the
runner only needs the step's answer, so a gantry step that lasts hours needs no change here
beyond ``step_timeout_s`` covering it.
"""

from __future__ import annotations

from collections.abc import Callable
import dataclasses
import datetime as dt
import math
from pathlib import Path
import time
from typing import Any, Protocol

import numpy as np

from growspace_sim.core.config import SimConfig
from growspace_sim.node.chamber_node import NOT_READY
from growspace_sim.rig.policies import make_policy, Twin
from growspace_sim.rig.rundir import format_progress, RunDir, RunDirError, RunSettings
from growspace_sim.ros import convert, types

RESET_ID_BASE = 1 << 20  # episode i is reset with reset_id RESET_ID_BASE + i + 1 (the node's
# own start-up episode is reset_id 0; a fixed id lets a resume find the episode in a recording)


class RunnerError(Exception):
    """The run cannot go on; the message says why and what a person can do."""


@dataclasses.dataclass
class Answer:
    """A chamber's answer to a reset or a step."""

    info: str  # '' = done; else why it was refused
    reward: float = 0.0
    terminated: bool = False
    truncated: bool = False
    step: int = 0  # the chamber's step count in the episode
    observation: np.ndarray | None = None


class RigChamber(Protocol):
    """A lockstep chamber the runner drives."""

    recording: Path | None  # where its recording is, if the runner can read it
    # A simulator: it can redo a step bit for bit, and the twin must equal it.
    simulated: bool

    def prepare(self) -> dict[int, list[RecordedStep]]:
        """Before a resume: make the recording readable (its writer gone, a damaged last file
        repaired) and return what it holds (``recorded_episodes``; empty without one)."""

    def start(self, resume: bool) -> None: ...

    def reset(self, reset_id: int, seed: int) -> Answer: ...

    def step(self, reset_id: int, step_id: int, action: int) -> Answer: ...

    def close(self) -> None: ...


def _utc(text: str) -> dt.datetime:
    """A journal time (ISO 8601, ``Z``) as an aware datetime."""
    return dt.datetime.fromisoformat(text.replace('Z', '+00:00'))


def reset_id_of(episode: int) -> int:
    """The reset_id episode ``episode`` (0-based) is sent with."""
    return RESET_ID_BASE + episode + 1


@dataclasses.dataclass
class RecordedStep:
    step: int
    step_id: int
    reward: float
    terminated: bool
    truncated: bool
    image: Any = None  # the BagMessage of its camera image, decoded on demand

    @property
    def observation(self) -> np.ndarray | None:
        return None if self.image is None else convert.image_from_msg(self.image.decode())


def recorded_episodes(path: Path | None) -> dict[int, list[RecordedStep]]:
    """The steps a finished recording holds of each episode (index 0 = its reset), by reset_id
    (the last episode with an id wins). Read before the chamber starts writing there again."""
    from growspace_sim.replay import Bag, read_episodes

    if path is None or not path.exists():
        return {}
    from growspace_sim.recording import split_files

    if path.is_dir() and not split_files(path):
        return {}
    out = {}
    with Bag(path) as bag:
        if not any(i.typename == types.STEP_RESULT for i in bag.topics.values()):
            return {}  # every message lost (a power cut before its first chunk)
        for episode in read_episodes(bag):
            out[episode.reset_id] = [RecordedStep(
                int(r.result.step), int(r.result.step_id), float(r.result.reward),
                bool(r.result.terminated), bool(r.result.truncated),
                r.outputs.get('camera/image_raw')) for r in episode.steps]
    return out


class Runner:
    """Runs (or resumes) the experiment of a run directory.

    Args:
        rundir: The run directory (its settings and journal).
        chamber: The chamber to drive.
        say: Where the progress lines go (one line per step, and what a person must do).
        clock: UTC now (tests replace it).
        sleep: Waits [s] (tests replace it).
        not_before: The hook for a schedule beyond the step period: given when a step would
            start (UTC), the earliest it may (e.g. the next lights-on of a photoperiod, so a
            step never runs into the night). None: the step period alone.
    """

    def __init__(self, rundir: RunDir, chamber: RigChamber, say: Callable[[str], None] = print,
                 clock: Callable[[], dt.datetime] | None = None,
                 sleep: Callable[[float], None] = time.sleep,
                 not_before: Callable[[dt.datetime], dt.datetime] | None = None) -> None:
        self.rundir = rundir
        self.settings: RunSettings = rundir.settings
        self.chamber = chamber
        self.say = say
        self.clock = clock or (lambda: dt.datetime.now(dt.UTC))
        self.sleep = sleep
        self.cfg = SimConfig(challenge=self.settings.challenge, setting=self.settings.setting)
        self.twin = Twin(self.cfg)
        self.policy = make_policy(self.settings.policy, self.settings.policy_path,
                                  self.settings.seed)
        self.observation: np.ndarray | None = None
        self._step_seconds: float | None = None
        self._next_at: dt.datetime | None = None
        self._sent_ids: dict[int, int] = {}  # reset_id -> highest step_id sent or journaled
        self._resend_pending = False  # after resuming an attached chamber (see _step)
        self.not_before = not_before

    # ------------------------------------------------------------------ the loop
    def run(self) -> None:
        """Run until every episode is done; resumes if the journal holds anything.

        Raises:
            RunnerError: The chamber answered what the journal cannot match, refused a
                reset for good, or was the runner's own sim_node and refused a step.
            RunDirError: The journal cannot be written.
        """
        state = self.rundir.state
        recording = self.chamber.recording
        # A chamber's recording without a journal: the runner died before its first event
        # (the reset it sent may be recorded); reconcile adopts what the chamber did.
        resuming = state.events > 0 or (recording is not None and recording.exists())
        recorded: dict[int, list[RecordedStep]] = {}
        if resuming:
            recorded = self.chamber.prepare()  # its recording finished, repaired and read
        self.chamber.start(resume=resuming)
        if resuming:
            self.reconcile(recorded)
            begun = self.rundir.state.last_intent_t
            if begun:  # the period holds across a restart
                self._next_at = _utc(begun) + dt.timedelta(seconds=self.settings.step_period_s)
        while True:
            state = self.rundir.state
            episode = state.current
            if episode is None:
                index = state.episodes[-1].index + 1 if state.episodes else 0
                if index >= self.settings.episodes:
                    break
                self._reset(index)
                continue
            self._step(episode)

    def _reset(self, index: int) -> None:
        seed = self.settings.episode_seed(index)
        reset_id = reset_id_of(index)
        answer = self._accepted_reset(index, reset_id, seed)
        self.twin.reset(index, seed)
        self.rundir.append('reset', episode=index, reset_id=reset_id, seed=seed)
        self.observation = answer.observation

    def _step(self, episode: Any) -> None:
        step = len(episode.steps) + 1
        pending = self.rundir.state.pending
        if not (pending and int(pending['step']) == step
                and int(pending['episode']) == episode.index):
            pending = None
        # A step in progress at a crash is redone with its journaled action (the same one the
        # policy gives; kept for a policy that is not). Right after resuming an attached
        # chamber, with its own step_id: a chamber that did it refuses it as a duplicate.
        resend = pending is not None and self._resend_pending
        self._resend_pending = False
        if not resend:  # a resent step was due when it was first begun
            self._wait_for_step_time()
        step_id = int(pending['step_id']) if resend else self._new_step_id(episode)
        action = int(pending['action']) if pending else \
            int(self.policy.act(self.observation, self.twin))
        started = _utc(pending['t']) if resend and pending.get('t') else self.clock()
        # The period counts from a step's start (a resent one: when it was first begun).
        self._next_at = started + dt.timedelta(seconds=self.settings.step_period_s)
        if not resend:
            self.rundir.append('intent', episode=episode.index, step=step, step_id=step_id,
                               action=action)
        answer = self.chamber.step(episode.reset_id, step_id, action)
        if answer.info and resend and answer.step == step:
            # The chamber had done it (its step count says so) and refused the duplicate: the
            # step happened once; its answer was lost with the runner (it is in the chamber's
            # recording). Journaled without a reward; the next action sees the last photo.
            self._complete(episode, step, step_id, action,
                           Answer('', math.nan, truncated=step >= self.cfg.episode_length))
            self.rundir.append('note', text=f'episode {episode.index + 1} step {step} was done '
                               f'by the chamber before the crash; its answer was lost (see the '
                               f"chamber's recording, step_id {step_id}).")
            return
        if answer.info:
            self._refused(episode, step, step_id, answer.info)
            return
        self._complete(episode, step, step_id, action, answer)
        elapsed = (self.clock() - started).total_seconds()
        self._step_seconds = elapsed if self._step_seconds is None else \
            0.8 * self._step_seconds + 0.2 * elapsed
        self.say(format_progress(self.settings, self.rundir.state, self.cfg.episode_length,
                                 self.clock(), self._next_at, self._step_seconds))

    def _complete(self, episode: Any, step: int, step_id: int, action: int,
                  answer: Answer) -> None:
        outcome = self.twin.step(action)
        self.rundir.append('step', episode=episode.index, step=step, step_id=step_id,
                           action=action, reward=answer.reward, terminated=answer.terminated,
                           truncated=answer.truncated)
        self.observation = answer.observation
        if self.chamber.simulated and outcome.reward != answer.reward:
            # On sim_node the twin is the chamber bit for bit; a difference is a bug to report.
            self.rundir.append('note', text=f'episode {episode.index + 1} step {step}: the twin '
                               f'gave reward {outcome.reward!r}, the chamber {answer.reward!r}')

    def _accepted_reset(self, index: int, reset_id: int, seed: int) -> Answer:
        """Reset episode ``index``. A gantry not ready (still starting, in alarm or e-stop) is
        waited out as a refused step is, and the same reset_id goes again (a refused reset
        changed nothing); any other refusal (a layout beyond the travel, a bad argument)
        would be refused again, so it ends the run."""
        while True:
            answer = self.chamber.reset(reset_id, seed)
            if not answer.info:
                return answer
            what = f'the reset of episode {index + 1} (reset_id {reset_id}, seed {seed})'
            if self.chamber.simulated or not answer.info.startswith(f'error: {NOT_READY}'):
                raise RunnerError(f'the chamber refused {what}: {answer.info}')
            self._wait_for_a_person(what, answer.info)

    def _refused(self, episode: Any, step: int, step_id: int, info: str) -> None:
        if self.chamber.simulated:
            raise RunnerError(f'sim_node refused step {step} of episode {episode.index + 1} '
                              f'(step_id {step_id}): {info}')
        self._wait_for_a_person(f'episode {episode.index + 1} step {step}', info)
        self._next_at = None  # the retry goes as soon as the retry period is over

    def _wait_for_a_person(self, what: str, info: str) -> None:
        text = (f'{what} was refused by the chamber: {info}. If the gantry is in alarm or '
                f'e-stop, a person must look at it and clear it (gantry/unlock, gantry/home); '
                f'the runner tries again every {self.settings.retry_period_s:g} s.')
        self.rundir.append('note', text=text)
        self.say(f'WAITING FOR A PERSON: {text}')
        self.sleep(self.settings.retry_period_s)

    def _new_step_id(self, episode: Any) -> int:
        pending = self.rundir.state.pending
        used = max(episode.last_step_id, self._sent_ids.get(episode.reset_id, 0),
                   int(pending['step_id']) if pending else 0)
        self._sent_ids[episode.reset_id] = used + 1
        return used + 1

    def _wait_for_step_time(self) -> None:
        now = self.clock()
        at = max(self._next_at or now, now)
        if self.not_before is not None:
            scheduled, at = at, max(at, self.not_before(at))
            if at > scheduled:
                self.say(f'the schedule holds the next step until '
                         f'{at.astimezone(dt.UTC):%Y-%m-%d %H:%M:%S} UTC')
        remaining = (at - now).total_seconds()
        if remaining > 0:
            self.sleep(remaining)

    # ------------------------------------------------------------------ resume
    def reconcile(self, recorded_by_id: dict[int, list[RecordedStep]]) -> None:
        """Make the journal and the chamber agree after a restart (see the module doc).

        Args:
            recorded_by_id: What the chamber's recording holds (``recorded_episodes``), read
                before the chamber started again; empty without a recording.

        Raises:
            RunnerError: They cannot agree (the recording holds steps the journal never
                sent, or a re-simulated reward differs from the journaled one).
        """
        self._resend_pending = self.chamber.recording is None
        adopted = self._adopt(recorded_by_id)
        caught_up = self._fill(recorded_by_id) if self.chamber.recording is not None else 0
        self.rundir.append('resume', adopted=adopted, caught_up=caught_up)
        current = self.rundir.state.current
        where = f'episode {current.index + 1} after step {len(current.steps)}' if current \
            else 'between episodes'
        self.say(f'resumed {where}'
                 + (f'; adopted from the recording: {", ".join(adopted)}' if adopted else '')
                 + (f'; {caught_up} step(s) re-simulated into the recording' if caught_up
                    else ''))

    def _adopt(self, recorded_by_id: dict[int, list[RecordedStep]]) -> list[str]:
        """Journal what the chamber did that the journal lacks (a reset, or the step in
        progress), from its recording; set the twin to the journal's last step."""
        state = self.rundir.state
        adopted: list[str] = []
        episode = state.current
        if episode is None:  # between episodes: was the next reset answered already?
            index = state.episodes[-1].index + 1 if state.episodes else 0
            if index < self.settings.episodes and recorded_by_id.get(reset_id_of(index)):
                seed = self.settings.episode_seed(index)
                self.rundir.append('reset', episode=index, reset_id=reset_id_of(index),
                                   seed=seed)
                adopted.append(f'the reset of episode {index + 1}')
                episode = self.rundir.state.current
            if episode is None:
                return adopted
        self.twin.reset(episode.index, episode.seed)
        for done in episode.steps:
            self.twin.step(int(done.action))
        recorded = recorded_by_id.get(episode.reset_id)
        if not recorded:
            return adopted
        last, known, pending = recorded[-1], len(episode.steps), state.pending
        if last.step > known + 1 or (last.step == known + 1 and pending is None):
            raise RunnerError(f'resume: the recording holds step {last.step} of episode '
                              f'{episode.index + 1} but the journal knows {known} steps and '
                              f"no step in progress: this recording is not the run's.")
        if last.step == known + 1:  # answered before the crash: adopt, never resend
            self._complete(episode, last.step, last.step_id, int(pending['action']), Answer(
                '', last.reward, last.terminated, last.truncated, last.step,
                last.observation))
            adopted.append(f'step {last.step} of episode {episode.index + 1}')
        elif last.step == known:
            self.observation = last.observation
        return adopted

    def _fill(self, recorded_by_id: dict[int, list[RecordedStep]]) -> int:
        """Re-simulate into the recording the journaled steps it lost (its last file cut short,
        or set aside): from the last episode it holds, to the journal's end; a lost reset is
        sent again. Every earlier file was finished, so nothing before that is missing."""
        episodes = self.rundir.state.episodes
        held = [i for i, e in enumerate(episodes) if recorded_by_id.get(e.reset_id)]
        first = held[-1] if held else 0
        count = 0
        for episode in episodes[first:]:
            recorded = recorded_by_id.get(episode.reset_id)
            if recorded:
                after = recorded[-1].step
            else:
                answer = self._accepted_reset(episode.index, episode.reset_id, episode.seed)
                self.observation = answer.observation
                after = 0
            count += self._catch_up(episode, after)
        return count

    def _catch_up(self, episode: Any, after: int) -> int:
        """Send the journaled steps after ``after`` again to a resumed simulator (their state was
        lost with the recording's tail) and check each reward bit for bit."""
        if not self.chamber.simulated:
            raise RunnerError(f"resume: the chamber's recording lacks steps {after + 1}.."
                              f'{len(episode.steps)} of episode {episode.index + 1} that the '
                              f'journal holds; only a simulator can redo them.')
        count = 0
        for done in episode.steps[after:]:
            answer = self.chamber.step(episode.reset_id, done.step_id, int(done.action))
            same = np.float64(answer.reward).tobytes() == np.float64(done.reward).tobytes()
            if answer.info or not same:
                raise RunnerError(f'resume: re-simulating step {done.step} of episode '
                                  f'{episode.index + 1} gave {answer.info or answer.reward!r}, '
                                  f'the journal holds reward {done.reward!r}.')
            self.observation = answer.observation
            count += 1
        return count


__all__ = ['Answer', 'RESET_ID_BASE', 'RigChamber', 'RunDirError', 'Runner', 'RunnerError',
           'recorded_episodes', 'reset_id_of']
