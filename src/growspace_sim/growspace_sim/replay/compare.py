"""Compare the applied light of two recordings step by step: a simulated run and the same
commands replayed onto the LED gantry (or any two runs of the same commands).

Steps are matched by (episode, step_id), never by their order or count: a step the gantry
refused has no light in its recording, and every later step must still meet its own step_id.
"""

from __future__ import annotations

import dataclasses
import math
import os

from growspace_sim.replay.bag import Bag
from growspace_sim.replay.episodes import Episode, read_episodes
from growspace_sim.ros import convert

BEAM_FIELDS = ('x', 'width')  # what a beam's light/state means (z and radius are unused)
SPOT_FIELDS = ('x', 'z', 'radius')


@dataclasses.dataclass
class FieldError:
    """How far one light field of B was from A over the compared steps [m]."""

    max_abs: float = 0.0
    sum_sq: float = 0.0
    count: int = 0
    worst: str = ''  # 'episode E, step_id S' of the largest difference

    @property
    def rms(self) -> float:
        return math.sqrt(self.sum_sq / self.count) if self.count else 0.0

    def add(self, difference: float, where: str) -> None:
        if abs(difference) > self.max_abs or not self.count:
            self.max_abs, self.worst = abs(difference), where
        self.sum_sq += difference * difference
        self.count += 1


@dataclasses.dataclass
class Comparison:
    """Light of recording B against recording A, matched by episode (order) and step_id."""

    steps: int = 0  # steps whose light/state both recordings hold
    errors: dict[str, FieldError] = dataclasses.field(default_factory=dict)
    unmatched: list[str] = dataclasses.field(default_factory=list)  # steps only one side has
    skipped: list[str] = dataclasses.field(default_factory=list)  # damaged or mismatched modes

    def within(self, tolerance_m: float) -> bool:
        """Whether every compared field stayed within ``tolerance_m`` of A."""
        return all(e.max_abs <= tolerance_m for e in self.errors.values())


def compare(path_a: str | os.PathLike, path_b: str | os.PathLike, *,
            namespace_a: str | None = None, namespace_b: str | None = None) -> Comparison:
    """Compare the applied light (``light/state``) of two recordings.

    Episodes are matched by their order in each file and steps by their step_id within the
    episode (the step number in a realtime recording, whose step_ids are 0), so B may come from
    another machine and clock (a bag replayed onto the gantry at one step an hour) and miss
    steps (refused there): those are listed, per run of step_ids, as only in A or only in B.
    Beams compare x and width, spotlights x, z and radius.

    Args:
        path_a: The reference recording (e.g. the simulated run).
        path_b: The recording to compare with it (e.g. the gantry's).
        namespace_a: Chamber namespace in A; None = the only one.
        namespace_b: Chamber namespace in B; None = the only one.

    Returns:
        The errors per field, and the steps that could not be compared, with why.

    Raises:
        ReplayError: A recording cannot be read.
    """
    with Bag(path_a) as bag:
        episodes_a = read_episodes(bag, namespace_a)
    with Bag(path_b) as bag:
        episodes_b = read_episodes(bag, namespace_b)
    out = Comparison()
    for index in range(max(len(episodes_a), len(episodes_b))):
        if index >= len(episodes_a) or index >= len(episodes_b):
            side = 'A' if index < len(episodes_a) else 'B'
            out.unmatched.append(f'episode {index}: only in {side}')
            continue
        a, b = episodes_a[index], episodes_b[index]
        for episode, side in ((a, 'A'), (b, 'B')):
            if episode.damaged:
                out.skipped.append(f'episode {index} of {side} is incomplete: '
                                   f'{"; ".join(episode.damaged)}')
        _compare_episode(index, a, b, out)
    return out


def _compare_episode(index: int, a: Episode, b: Episode, out: Comparison) -> None:
    lights_a, lights_b = _lights(a), _lights(b)
    for side, mine, other in (('A', lights_a, lights_b), ('B', lights_b, lights_a)):
        only = sorted(set(mine) - set(other))
        out.unmatched += [f'episode {index}, step_id {_span(run)}: only in {side}'
                          for run in _runs(only)]
    for step in sorted(set(lights_a) & set(lights_b)):
        where = f'episode {index}, step_id {step}'
        light_a, light_b = lights_a[step], lights_b[step]
        if light_a.mode != light_b.mode:
            out.skipped.append(f'{where}: light mode {light_a.mode} in A, {light_b.mode} in B')
            continue
        fields = SPOT_FIELDS if light_a.mode == convert.MODE_SPOT else BEAM_FIELDS
        for name in fields:
            out.errors.setdefault(name, FieldError()).add(
                float(getattr(light_b, name)) - float(getattr(light_a, name)), where)
        out.steps += 1


def _lights(episode: Episode) -> dict[int, object]:
    """step_id (the step number where step_ids are 0: realtime) -> the decoded light/state."""
    return {int(record.result.step_id) or int(record.result.step):
            record.outputs['light/state'].decode()
            for record in episode.steps if 'light/state' in record.outputs}


def _runs(ids: list[int]) -> list[list[int]]:
    """Consecutive runs of sorted ids: [1, 2, 3, 7] -> [[1, 2, 3], [7]]."""
    runs: list[list[int]] = []
    for i in ids:
        if runs and i == runs[-1][-1] + 1:
            runs[-1].append(i)
        else:
            runs.append([i])
    return runs


def _span(run: list[int]) -> str:
    return f'{run[0]}' if len(run) == 1 else f'{run[0]}-{run[-1]}'


def format_comparison(result: Comparison) -> str:
    """A table of the errors in mm, then the steps that were not compared."""
    lines = [f'{result.steps} step(s) compared (light/state of B minus A)',
             f'{"field":>7} {"max |d| [mm]":>13} {"RMS [mm]":>9}  worst at']
    for name, error in result.errors.items():
        lines.append(f'{name:>7} {error.max_abs * 1e3:>13.3f} {error.rms * 1e3:>9.3f}  '
                     f'{error.worst}')
    lines += [f'not compared: {line}' for line in result.skipped + result.unmatched]
    return '\n'.join(lines)
