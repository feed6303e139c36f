"""An experiment's run directory: its settings, its journal of completed steps, its recording.

Layout (``growspace-rig run RUN_DIR``)::

    RUN_DIR/run.json        the settings, written once (atomically) when the run is created
    RUN_DIR/journal.jsonl   one JSON line per event, appended and fsynced before going on
    RUN_DIR/recording/      the chamber's recording, split by size and duration

The journal is the run's memory across crashes (design: shared/design/rig-runs.md, item 1:
intent before acting, completion after):

- ``reset``: an episode started (its reset was answered): ``episode``, ``reset_id``, ``seed``;
- ``intent``: a step is about to be sent: ``episode``, ``step`` (1-based in the episode),
  ``step_id`` (the lockstep id it is sent with), ``action``;
- ``step``: the chamber answered it: the same plus ``reward``, ``terminated``, ``truncated``;
- ``resume``, ``note``: what a resume found and did, a person's attention needed (information).

Every line is written with one ``write`` and fsynced before the runner acts on it, so after a
crash the journal holds every completed step and at most one step in progress (an intent
without its completion). A line cut short by the crash is no event: it is ignored when read and
cut off before the next append. Times are UTC (ISO 8601, ``Z``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import functools
import json
import math
import os
from pathlib import Path
import secrets
from typing import Any

from growspace_sim.core.photoperiod import Photoperiod
from growspace_sim.rig.faults import armed, stop_if_due

RUN_FILE = 'run.json'
JOURNAL_FILE = 'journal.jsonl'
RECORDING_DIR = 'recording'
CHAMBERS = ('sim', 'attach')
POLICY_KINDS = ('oracle', 'random', 'replay', 'model')


class RunDirError(Exception):
    """A run directory that cannot be created, read or continued; the message says why.

    Attributes:
        field: The ``RunSettings`` field a bad setting names ('' for other errors).
    """

    def __init__(self, message: str, field: str = '') -> None:
        super().__init__(message)
        self.field = field


def utc_now() -> str:
    """Now in UTC, ISO 8601 with a ``Z`` (the journal's and run.json's times)."""
    return dt.datetime.now(dt.UTC).isoformat(timespec='seconds').replace('+00:00', 'Z')


@dataclasses.dataclass(frozen=True)
class RunSettings:
    """What an experiment is; stored in ``run.json`` and never changed by a resume.

    Attributes:
        policy: ``oracle``, ``random``, ``replay`` (the actions of a recorded episode) or
            ``model`` (a growspace-train run directory).
        policy_path: The recording (``replay``) or run directory (``model``); '' otherwise.
        challenge: The challenge, e.g. ``control``.
        setting: ``easy`` or ``hard``.
        episodes: Episodes to run.
        seed: Episode i is reset with seed ``seed + i``; random actions are seeded with it too.
        chamber: ``sim`` (the runner starts sim_node, recording into the run directory) or
            ``attach`` (a running lockstep chamber: sim_node, or gantry_node with camera_node).
        namespace: The chamber namespace: the one to attach to, or (``sim``) the one the
            runner's sim_node uses for the whole run (chosen when the run is created).
        step_period_s: At least this long from one step's start to the next [s]; 0 = as soon
            as the chamber answered (a simulator), e.g. 3600 on the rig.
        step_timeout_s: How long one step may take to be answered [s].
        retry_period_s: ``attach``: how often a step the chamber refused (an alarm, an e-stop:
            a person must clear it) is tried again [s].
        record_max_bytes: Split the recording into files of this many message bytes (0 = no).
        record_max_duration_s: ... and of at most this much log time [s] (0 = no limit).
        lights_on, lights_off, utc_offset_h: A photoperiod the runner keeps (``schedule.py``):
            no step begins in the night ('' and '': none; for sim_node, the gantry has its own).
        created: When the run was created (UTC).
    """

    policy: str = 'oracle'
    policy_path: str = ''
    challenge: str = 'control'
    setting: str = 'easy'
    episodes: int = 1
    seed: int = 0
    chamber: str = 'sim'
    namespace: str = ''
    step_period_s: float = 0.0
    step_timeout_s: float = 600.0
    retry_period_s: float = 30.0
    record_max_bytes: int = 64 * 1024 * 1024
    record_max_duration_s: float = 0.0
    lights_on: str = ''
    lights_off: str = ''
    utc_offset_h: float = 0.0
    created: str = ''

    def __post_init__(self) -> None:
        def bad(name: str, allowed: str) -> RunDirError:
            return RunDirError(f'{name} = {getattr(self, name)!r} is not allowed; {allowed}.',
                               field=name)
        if self.policy not in POLICY_KINDS:
            raise bad('policy', f'one of {", ".join(POLICY_KINDS)}')
        if self.policy in ('replay', 'model') and not self.policy_path:
            raise bad('policy_path', f'policy {self.policy} needs the path of a '
                      f'{"recording" if self.policy == "replay" else "growspace-train run"}')
        if self.chamber not in CHAMBERS:
            raise bad('chamber', f'one of {", ".join(CHAMBERS)}')
        if self.chamber == 'attach' and not self.namespace:
            raise bad('namespace', 'attaching needs the chamber namespace, e.g. /growspace')
        for name in ('episodes',):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise bad(name, 'an integer >= 1')
        for name in ('seed', 'record_max_bytes'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise bad(name, 'an integer >= 0')
        for name in ('step_period_s', 'record_max_duration_s'):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise bad(name, 'a finite number >= 0')
        try:
            self.photoperiod  # noqa: B018 - both times or neither, HH:MM, a length
        except ValueError as e:
            raise RunDirError(str(e), field='lights_on') from None
        for name in ('step_timeout_s', 'retry_period_s'):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise bad(name, 'a finite number > 0')

    @property
    def photoperiod(self) -> Photoperiod:
        return Photoperiod(self.lights_on, self.lights_off, self.utc_offset_h)

    def episode_seed(self, episode: int) -> int:
        """The seed episode ``episode`` (0-based) is reset with."""
        return self.seed + episode

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> RunSettings:
        """Settings from ``run.json``; unknown keys are an error (a newer version's run)."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise RunDirError(f'run.json has settings this version does not know: {unknown}.')
        return cls(**data)


@dataclasses.dataclass
class StepDone:
    """A completed step, as the journal holds it."""

    step: int  # 1-based in its episode
    step_id: int  # the lockstep id it was sent with
    action: Any
    reward: float
    terminated: bool
    truncated: bool


@dataclasses.dataclass
class EpisodeState:
    """One episode as far as the journal knows it."""

    index: int  # 0-based
    reset_id: int
    seed: int
    steps: list[StepDone] = dataclasses.field(default_factory=list)

    @property
    def done(self) -> bool:
        return bool(self.steps) and (self.steps[-1].terminated or self.steps[-1].truncated)

    @property
    def last_step_id(self) -> int:
        return self.steps[-1].step_id if self.steps else 0

    @property
    def episode_return(self) -> float:
        return float(sum(s.reward for s in self.steps))


@dataclasses.dataclass
class JournalState:
    """What the journal says: the episodes started, their completed steps, a step in progress.

    Attributes:
        episodes: Every episode whose reset was answered, in order.
        pending: The last ``intent`` without its ``step`` (a step in progress at a crash).
        last_intent_t: When the last step was begun: a resume keeps the step period from it.
        duplicated: Steps journaled twice (must stay 0; counted, never hidden).
        events: Lines read (torn lines excluded).
        torn: A last line cut short by a crash was ignored.
    """

    episodes: list[EpisodeState] = dataclasses.field(default_factory=list)
    pending: dict[str, Any] | None = None
    last_intent_t: str | None = None  # when the last step was begun (UTC, ISO 8601)
    duplicated: int = 0
    events: int = 0
    torn: bool = False

    @property
    def steps_done(self) -> int:
        return sum(len(e.steps) for e in self.episodes)

    @property
    def current(self) -> EpisodeState | None:
        """The episode in progress (started, not done), or None."""
        if self.episodes and not self.episodes[-1].done:
            return self.episodes[-1]
        return None

    @property
    def episodes_done(self) -> int:
        return sum(1 for e in self.episodes if e.done)


def read_journal(path: str | os.PathLike) -> JournalState:
    """Read a journal (a missing file is an empty journal).

    Raises:
        RunDirError: A line other than the last is not a journal event (the file was edited
            or damaged otherwise than by a crash).
    """
    state = JournalState()
    try:
        text = Path(path).read_bytes().decode('utf-8', 'replace')
    except FileNotFoundError:
        return state
    lines = text.split('\n')
    complete, tail = lines[:-1], lines[-1]  # a last line without its newline was cut short
    state.torn = bool(tail)
    for number, line in enumerate(complete, 1):
        if not line.strip():
            continue
        try:
            event = json.loads(line)
            _apply(state, event)
        except (ValueError, KeyError, TypeError) as e:
            raise RunDirError(f'{path}:{number}: not a journal event ({e}): {line[:120]!r}') \
                from e
        state.events += 1
    return state


def _apply(state: JournalState, event: dict[str, Any]) -> None:
    kind = event['event']
    if kind == 'reset':
        index = int(event['episode'])
        if state.episodes and state.episodes[-1].index == index:
            state.episodes[-1] = EpisodeState(index, int(event['reset_id']), int(event['seed']))
        else:
            state.episodes.append(EpisodeState(index, int(event['reset_id']),
                                               int(event['seed'])))
        state.pending = None
    elif kind == 'intent':
        state.pending = event
        state.last_intent_t = event.get('t')
    elif kind == 'step':
        episode = next(e for e in reversed(state.episodes) if e.index == int(event['episode']))
        reward = event['reward']  # null: the answer was lost (the chamber's recording has it)
        done = StepDone(int(event['step']), int(event['step_id']), event['action'],
                        math.nan if reward is None else float(reward), bool(event['terminated']),
                        bool(event['truncated']))
        if any(s.step == done.step for s in episode.steps):
            state.duplicated += 1
        else:
            episode.steps.append(done)
        state.pending = None
    elif kind not in ('resume', 'note'):
        raise ValueError(f'unknown event {kind!r}')


class RunDir:
    """A run directory: create it once, open it again to resume.

    Args:
        path: The directory.

    Raises:
        RunDirError: It is not a run directory (no ``run.json``), or its files cannot be read.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        run_file = self.path / RUN_FILE
        try:
            data = json.loads(run_file.read_text())
        except FileNotFoundError:
            raise RunDirError(f'{self.path} is not a run directory (no {RUN_FILE}); '
                              f'`growspace-rig run` creates one.') from None
        except (OSError, ValueError) as e:
            raise RunDirError(f'{run_file} cannot be read: {e}') from e
        self.settings = RunSettings.from_json(data)
        self.state = read_journal(self.journal_path)
        if self.state.torn:
            self._cut_torn_line()

    @classmethod
    def create(cls, path: str | os.PathLike, settings: RunSettings) -> RunDir:
        """Make a new run directory with its ``run.json``; never reuses an existing one.

        Raises:
            RunDirError: The directory exists (resume it instead) or cannot be created.
        """
        path = Path(path)
        armed(error=RunDirError)  # a bad fault-injection setting: refused before anything
        try:
            path.mkdir(parents=True)  # refuses an existing directory atomically
        except FileExistsError:
            raise RunDirError(f'{path} exists already; `growspace-rig resume {path}` goes on '
                              f'with it, or choose a new directory.') from None
        except OSError as e:
            raise RunDirError(f'cannot create {path}: {e.strerror or e}') from e
        if not settings.created:
            settings = dataclasses.replace(settings, created=utc_now())
        if settings.chamber == 'sim' and not settings.namespace:
            # One namespace for the run's whole life: its recording is one chamber's.
            settings = dataclasses.replace(
                settings, namespace=f'/growspace_rig_{secrets.token_hex(4)}')
        write_atomically(path / RUN_FILE,
                         json.dumps(dataclasses.asdict(settings), indent=2) + '\n')
        return cls(path)

    @property
    def journal_path(self) -> Path:
        return self.path / JOURNAL_FILE

    @property
    def recording_path(self) -> Path:
        return self.path / RECORDING_DIR

    def append(self, event: str, **fields: Any) -> None:
        """Append one event to the journal and fsync it (then update ``state``).

        Raises:
            RunDirError: It could not be written (a full disk): the runner must stop, since
                acting without the journal would lose the step; or a bad ``faults.PAUSE_ENV``.
        """
        pause_at = self._pause_at  # (before the line: a bad value writes nothing)
        record = {'event': event, 't': utc_now(), **fields}
        if isinstance(record.get('reward'), float) and math.isnan(record['reward']):
            record['reward'] = None  # JSON has no NaN
        line = json.dumps(record, separators=(',', ':')) + '\n'
        try:
            fd = os.open(self.journal_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
            try:
                if os.write(fd, line.encode()) != len(line.encode()):
                    raise OSError('short write')
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError as e:
            raise RunDirError(f'cannot write the journal {self.journal_path}: '
                              f'{e.strerror or e}') from e
        _apply(self.state, record)
        self.state.events += 1
        stop_if_due(pause_at, event, self.state.steps_done)

    @functools.cached_property
    def _pause_at(self) -> tuple[str, int] | None:
        """The fault-injection pause (``faults.PAUSE_ENV``), read at the first append."""
        return armed(say=True, error=RunDirError)

    def _cut_torn_line(self) -> None:
        """Drop a last line cut short by a crash, so the next event starts on its own line."""
        data = self.journal_path.read_bytes()
        keep = data.rfind(b'\n') + 1
        with open(self.journal_path, 'r+b') as stream:
            stream.truncate(keep)
            stream.flush()
            os.fsync(stream.fileno())
        self.state.torn = False


def write_atomically(path: Path, text: str) -> None:
    """Write a file so that a crash leaves the old content or the new one, never a part."""
    temporary = path.with_name(path.name + '.tmp')
    with open(temporary, 'w') as stream:
        stream.write(text)
        stream.flush()
        os.fsync(stream.fileno())
    os.replace(temporary, path)
    fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    with contextlib.suppress(FileNotFoundError):
        temporary.unlink()


def format_progress(settings: RunSettings, state: JournalState, episode_length: int,
                    now: dt.datetime, next_step_at: dt.datetime | None,
                    seconds_per_step: float | None) -> str:
    """One line a person reads: where the run is, when the next step is, when it ends (UTC).

    Args:
        settings: The run's settings.
        state: The journal.
        episode_length: Steps per episode.
        now: The current time (UTC, aware).
        next_step_at: When the next step starts; None = now.
        seconds_per_step: The measured time per step, for the ETA; None = not known yet.

    Returns:
        e.g. ``episode 2/5 step 17/50 | 67/250 steps done | next step 14:05 UTC |
        ETA 2026-11-29 03:10 UTC``.
    """
    total = settings.episodes * episode_length
    done = state.steps_done
    current = state.current
    finished = state.episodes_done >= settings.episodes
    if current is not None or finished:
        last = current or state.episodes[-1]
        episode, step = last.index + 1, len(last.steps)
    elif state.episodes:
        episode, step = state.episodes[-1].index + 2, 0
    else:
        episode, step = 1, 0
    parts = [f'episode {episode}/{settings.episodes} step {step}/{episode_length}',
             f'{done}/{total} steps done']
    if finished:
        parts.append('finished')
        return ' | '.join(parts)
    at = next_step_at or now
    parts.append(f'next step {at.astimezone(dt.UTC):%H:%M:%S} UTC')
    # Episodes may end early (terminated); the ETA assumes they run to their length.
    remaining = (settings.episodes - state.episodes_done) * episode_length - \
        (len(current.steps) if current is not None else 0)
    if seconds_per_step is not None:
        period = max(seconds_per_step, settings.step_period_s)
        eta = at + dt.timedelta(seconds=period * max(remaining - 1, 0) + seconds_per_step)
        parts.append(f'ETA {eta.astimezone(dt.UTC):%Y-%m-%d %H:%M:%S} UTC')
    return ' | '.join(parts)
