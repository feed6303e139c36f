"""Re-simulation: replay every recorded episode from its seed and commands, compare bit for bit."""

from __future__ import annotations

from collections.abc import Callable
import dataclasses
import os
from typing import Any

import numpy as np

from growspace_sim.recording import METADATA_NAME
from growspace_sim.recording.scan import Damage
from growspace_sim.replay.bag import Bag, ReplayError
from growspace_sim.replay.episodes import COMPARED, Episode, StepRecord, read_episodes
from growspace_sim.ros import convert
from growspace_sim.ros import types
from growspace_sim.ros.interface import digit_fingerprint
from growspace_sim.node.resume import ResumePoint
from growspace_sim.simulation import Simulation


@dataclasses.dataclass(frozen=True)
class Mismatch:
    episode: int
    step: int
    topic: str
    field: str
    detail: str

    def __str__(self) -> str:
        return (f'episode {self.episode}, step {self.step}, {self.topic}.{self.field}: '
                f'{self.detail}')


@dataclasses.dataclass
class ResimReport:
    episodes: int = 0
    steps: int = 0
    messages_compared: int = 0
    mismatch: Mismatch | None = None
    warnings: list[str] = dataclasses.field(default_factory=list)
    # Episodes that could not be checked (unreadable parts of the file), each with its reason
    unverified: list[str] = dataclasses.field(default_factory=list)
    unreadable: list[Damage] = dataclasses.field(default_factory=list)  # parts of the file

    @property
    def ok(self) -> bool:
        return self.mismatch is None and self.episodes > 0 and not self.unverified


def resimulate(path: str | os.PathLike, namespace: str | None = None, *,
               digit_source: str | None = None,
               progress: Callable[[int, int], None] | None = None) -> ResimReport:
    """Re-run every recorded episode and compare it with the recording, bit for bit.

    Per episode: the recorded config and seed reset a ``Simulation`` (a config change builds a
    new one that keeps the random stream, as the node does); per step, the recorded light
    commands are applied through ``convert.apply_command`` (in lockstep only the one whose
    step_id the result answers; in realtime mode the latest one) and the chamber steps.
    Images (bytes), plant states (node arrays, tips, counts), applied lights and rewards must
    equal the recorded ones exactly. Stops at the first mismatch. An episode that an unreadable
    part of the file touched is skipped and listed in ``unverified`` (so is a later one that
    continues its random stream); the others are still checked.

    Args:
        path: The ``.mcap`` file.
        namespace: The chamber namespace; None = the only one.
        digit_source: Override the recorded shape-digit source.
        progress: Called with (episodes done, episodes in total).

    Returns:
        The report; ``report.ok`` is True when everything matched.

    Raises:
        ReplayError: The file cannot be read, or lacks the config or seed to re-simulate.
    """
    report = ResimReport()
    with Bag(path) as bag:
        _replay(bag, namespace, digit_source, report, progress)
    return report


def resume_point(path: str | os.PathLike, namespace: str | None = None, *,
                 digit_source: str | None = None) -> ResumePoint:
    """Re-simulate a recording to its last step, bit for bit, so the chamber can go on from it.

    Every recorded episode is re-simulated from its seed and commands as ``resimulate`` does
    (the random stream of an episode reset without a seed depends on the earlier ones) and
    every step compared with the recording; the simulation is then where the recorded chamber
    was after its last recorded step.

    Args:
        path: The recording (a file or a split recording's directory).
        namespace: The chamber namespace; None = the only one.
        digit_source: Override the recorded shape-digit source.

    Returns:
        The resume point.

    Raises:
        ReplayError: The recording cannot be read, holds no episode, or does not re-simulate
            exactly (the message names the first mismatch or the unreadable part).
    """
    report = ResimReport()
    with Bag(path) as bag:
        sim, outcome, last = _replay(bag, namespace, digit_source, report, None)
    if report.mismatch is not None:
        raise ReplayError(f'{path} cannot be resumed: re-simulating it differs at '
                          f'{report.mismatch}.')
    if report.unverified:
        raise ReplayError(f'{path} cannot be resumed bit for bit: '
                          f'{"; ".join(report.unverified)}.')
    step_ids = [int(s.result.step_id) for s in last.stepped] + \
        [int(r.step_id) for r in last.rejected]
    return ResumePoint(sim, outcome, last.seed, last.reset_id, max(step_ids, default=0),
                       last.steps[-1].log_time, last.done, report)


def _replay(bag: Bag, namespace: str | None, digit_source: str | None, report: ResimReport,
            progress: Callable[[int, int], None] | None) -> tuple[Simulation, Any, Episode]:
    """Re-simulate and compare every episode of an open recording, filling ``report``.

    Returns:
        The simulation after the last step re-simulated, that step's outcome and its episode.
    """
    topics = bag.chamber_topics(namespace)
    for full in topics.values():
        recorded_hash = bag.topics[full].type_hash
        if recorded_hash and recorded_hash != types.type_hash(bag.topics[full].typename):
            report.warnings.append(f'{full}: recorded type hash {recorded_hash} differs '
                                   f"from this version's message definition.")
    meta = bag.metadata.get(METADATA_NAME, {})
    source = digit_source or meta.get('digit_source') or 'auto'
    lockstep = meta.get('mode') != 'realtime'
    episodes = read_episodes(bag, namespace)
    report.unreadable = list(bag.damage)
    if not episodes:
        raise ReplayError(f'{bag.path} holds no episode start (StepResult with step 0).')
    sim: Simulation | None = None
    outcome: Any = None
    stream_known = True  # the random stream is where the recording's was
    for episode in episodes:
        if episode.damaged or (episode.seed is None and not stream_known):
            why = '; '.join(episode.damaged) or 'it continues the random stream of an ' \
                'episode that could not be checked'
            report.unverified.append(f'episode {episode.index}: {why}')
            stream_known = False
            if progress is not None:
                progress(report.episodes + len(report.unverified), len(episodes))
            continue
        stream_known = True
        if episode.config is None:
            raise ReplayError(f'{bag.path}: episode {episode.index} has no recorded config '
                              f'(neither chamber/config nor "growspace" metadata).')
        if not episode.seed_known or (sim is None and episode.seed is None):
            raise ReplayError(f'{bag.path}: episode {episode.index} (reset_id '
                              f'{episode.reset_id}) has no recorded seed, so it cannot be '
                              f're-simulated.')
        if sim is None or sim.cfg != episode.config:
            try:
                sim = Simulation(episode.config, source) if sim is None \
                    else sim.with_config(episode.config)
            except FileNotFoundError as e:
                raise ReplayError(f'{bag.path}: episode {episode.index} needs the shape '
                                  f'digits of source {source!r}: {e}') from e
            fingerprint = meta.get('digit_fingerprint', '')
            current = digit_fingerprint(sim)
            if fingerprint and current and fingerprint != current:
                report.warnings.append(f'the shape digits differ from the recorded ones '
                                       f'(source {source!r}); images will not match.')
        outcome = sim.reset(seed=episode.seed)
        mismatch = _compare_step(sim, outcome, episode, episode.steps[0], report) \
            if episode.reset_recorded else None
        for record in episode.stepped:
            if mismatch is not None:
                break
            _apply_command(sim, record, lockstep)
            outcome = sim.step()
            mismatch = _compare_step(sim, outcome, episode, record, report)
            report.steps += 1
        report.episodes += 1
        if progress is not None:
            progress(report.episodes + len(report.unverified), len(episodes))
        if mismatch is not None:
            report.mismatch = mismatch
            break
    return sim, outcome, episode


def _apply_command(sim: Simulation, record: StepRecord, lockstep: bool) -> None:
    """Apply the command the node applied before this step, as the node chose it."""
    if lockstep:
        # The first command with the step_id the result answers; others were late or repeated.
        step_id = int(record.result.step_id)
        chosen = next((c for c in record.commands if int(c.step_id) == step_id), None)
    else:
        chosen = record.commands[-1] if record.commands else None  # the latest one wins
    if chosen is None:
        return
    try:
        convert.apply_command(sim, chosen)
    except ValueError:
        pass  # the node rejected it too and kept the light


def _compare_step(sim: Simulation, outcome: Any, episode: Episode, record: StepRecord,
                  report: ResimReport) -> Mismatch | None:
    result = record.result
    step = int(result.step)
    expected = {
        'camera/image_raw': convert.image_msg(sim.observe(), 0, ''),
        'plant/state': convert.plant_state_msg(sim.chamber, 0, 0, ''),
        'light/state': convert.light_msg(sim.chamber.light, 0, 0, ''),
        'step_result': convert.step_result_msg(outcome, step_id=0, reset_id=0,
                                               step=sim.chamber.steps, stamp_ns=0, frame_id=''),
    }
    for rel, fields in COMPARED.items():
        if rel == 'step_result':
            recorded = result
        elif rel in record.outputs:
            recorded = record.outputs[rel].decode()
        else:
            return Mismatch(episode.index, step, rel, '*', 'not recorded for this step')
        report.messages_compared += 1
        for name in fields:
            detail = _difference(getattr(recorded, name), getattr(expected[rel], name))
            if detail is not None:
                return Mismatch(episode.index, step, rel, name, detail)
    return None


def _difference(recorded: Any, simulated: Any) -> str | None:
    if isinstance(recorded, np.ndarray) or isinstance(simulated, np.ndarray):
        a, b = np.asarray(recorded), np.asarray(simulated)
        if a.shape != b.shape:
            return f'recorded {a.shape[0] if a.ndim else 1} elements, re-simulated ' \
                   f'{b.shape[0] if b.ndim else 1}'
        if a.dtype != b.dtype:
            b = b.astype(a.dtype)
        if a.tobytes() == b.tobytes():  # bit-identical, also for -0.0 and NaN
            return None
        differs = a != b
        if a.dtype.kind == 'f':
            differs |= np.signbit(a) != np.signbit(b)  # -0.0 == 0.0 but is not the same bits
        flat = np.flatnonzero(differs.reshape(-1))
        i = int(flat[0]) if flat.size else 0
        return f'[{i}] recorded {a.reshape(-1)[i]!r}, re-simulated {b.reshape(-1)[i]!r}'
    if isinstance(recorded, float) or isinstance(simulated, float):
        if np.float64(recorded).tobytes() == np.float64(simulated).tobytes():
            return None
        return f'recorded {recorded!r}, re-simulated {simulated!r}'
    if recorded != simulated:
        return f'recorded {recorded!r}, re-simulated {simulated!r}'
    return None
