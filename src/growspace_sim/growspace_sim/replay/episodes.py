"""The episodes of a recording (resets, commands, outputs) and its summary."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from typing import Any

from growspace_sim.agents.evaluation import episode_returns
from growspace_sim.core.config import SimConfig
from growspace_sim.recording import METADATA_NAME
from growspace_sim.recording.scan import Damage
from growspace_sim.replay.bag import Bag, BagMessage
from growspace_sim.ros.interface import NAMES

# Fields each topic's comparison covers: what the simulation decides, not the ids and stamps.
COMPARED = {
    NAMES['image']: ('height', 'width', 'encoding', 'step', 'data'),
    NAMES['plant']: ('step', 'node_x', 'node_z', 'parent', 'plant', 'tips', 'branch_count'),
    NAMES['light']: ('mode', 'x', 'z', 'width', 'radius'),
    NAMES['result']: ('step', 'reward', 'plant_rewards', 'terminated', 'truncated', 'success'),
}


@dataclasses.dataclass
class StepRecord:
    """One step (or the reset, step 0) as recorded: its result and the messages before it."""

    result: Any  # StepResult
    log_time: int
    outputs: dict[str, BagMessage]  # camera/image_raw, plant/state, light/state
    commands: list[Any]  # LightCommands received since the previous stepped result


@dataclasses.dataclass
class Episode:
    index: int  # 0-based position in the file
    reset_id: int
    config: SimConfig | None  # the effective config, if recorded (chamber/config or metadata)
    seed: int | None  # None: the random stream continued from the previous episode
    seed_known: bool  # False: no record says which seed (a partial recording)
    steps: list[StepRecord]  # steps[0] is the reset
    # StepResults answered without a step: rejected commands or resets, commands after the end
    rejected: list[Any] = dataclasses.field(default_factory=list)
    # False: steps[0] is a step, not the reset (its reset published no observation, as
    # gantry_node's start-up does not, or it was in an unreadable part of the file)
    reset_recorded: bool = True
    gaps: list[str] = dataclasses.field(default_factory=list)  # steps or reset missing
    unreadable: list[Damage] = dataclasses.field(default_factory=list)  # lost parts it overlaps

    @property
    def damaged(self) -> list[str]:
        """Why parts of this episode are missing; empty for an intact episode."""
        return self.gaps + [f'unreadable {part}' for part in self.unreadable]

    @property
    def stepped(self) -> list[StepRecord]:
        """The steps after the reset (all of ``steps`` when the reset was not recorded)."""
        return self.steps[1:] if self.reset_recorded else self.steps

    @property
    def n_steps(self) -> int:
        return len(self.stepped)

    @property
    def episode_return(self) -> float:
        """Added step by step, as the agent did (the same number as growspace-eval's)."""
        return float(episode_returns([[s.result.reward for s in self.stepped]])[0])

    @property
    def done(self) -> bool:
        last = self.steps[-1].result
        return bool(last.truncated or last.terminated)

    @property
    def duration_ns(self) -> int:
        return self.steps[-1].log_time - self.steps[0].log_time


def read_episodes(bag: Bag, namespace: str | None = None) -> list[Episode]:
    """Group a chamber's messages into episodes (a StepResult with step 0 starts one).

    A StepResult that no observation preceded answered a request without a step (a rejected
    command or reset, a command after the episode's end); it goes to ``Episode.rejected``, as
    does a StepResult whose ``info`` is an error (a gantry step that failed in its growth period
    or photo: not counted by the gantry, redone by the agent). Steps
    recorded before the first reset (a recorder that joined a running chamber) are dropped:
    without their reset they cannot be re-simulated.

    Where the file has unreadable parts (``Bag.damage``), every episode they touch lists why in
    ``Episode.damaged``: the byte offset of the lost chunk, steps missing from the numbering, a
    reset that was lost (the steps after it form an episode with ``reset_recorded`` False).
    Steps from step 1 on after a node's ``chamber/config`` but before any reset result form
    the node's first episode (gantry_node does not move, so publishes no reset, at start-up).

    Args:
        bag: The open recording.
        namespace: The chamber namespace; None = the only one.

    Returns:
        The episodes in recorded order.
    """
    topics = bag.chamber_topics(namespace)
    rel_of = {full: rel for rel, full in topics.items()}
    meta = bag.metadata.get(METADATA_NAME, {})
    base_cfg = _config_from_json(meta.get('config')) if meta.get('config') else None
    first_seed = int(meta['seed']) if meta.get('seed') else None
    episodes: list[Episode] = []
    requests: dict[int, Any] = {}
    fresh_config: dict | None = None
    commands: list[Any] = []
    outputs: dict[str, BagMessage] = {}
    cfg = base_cfg
    for msg in bag.messages(topics.values()):
        rel = rel_of[msg.topic]
        if rel == NAMES['reset']:
            request = msg.decode()
            requests[int(request.reset_id)] = request
        elif rel == NAMES['config']:
            try:
                fresh_config = json.loads(msg.decode().data)
            except ValueError:
                fresh_config = None
        elif rel == NAMES['command']:
            commands.append(msg.decode())
        elif rel in COMPARED and rel != NAMES['result']:
            outputs[rel] = msg
        elif rel == NAMES['result']:
            result = msg.decode()
            if result.info.startswith('error'):
                # A step that failed after its outputs (gantry_node: a fault in its growth
                # period, no photo): not done, the agent redoes it; its outputs stay unmatched.
                outputs = {}
            if not outputs:
                # Nothing changed; the commands so far still count (realtime: the latest one
                # applies at the next tick).
                if episodes:
                    episodes[-1].rejected.append(result)
                continue
            record = StepRecord(result, msg.log_time, outputs, commands)
            outputs, commands = {}, []
            if result.step == 0:
                seed, known = None, True
                request = requests.get(int(result.reset_id))
                if fresh_config is not None:
                    cfg = _config_from_json(fresh_config.get('config')) or cfg
                    seed = fresh_config.get('seed')
                elif request is not None:
                    changes = {k: getattr(request, k) for k in ('challenge', 'setting')
                               if getattr(request, k)}
                    cfg = cfg.replace(**changes) if cfg is not None and changes else cfg
                    seed = int(request.seed) if request.has_seed else None
                elif not episodes:
                    seed, known = first_seed, first_seed is not None
                else:
                    known = False
                fresh_config = None
                episodes.append(Episode(len(episodes), int(result.reset_id), cfg, seed, known,
                                        [record]))
            elif episodes and int(result.reset_id) == episodes[-1].reset_id \
                    and result.step > episodes[-1].steps[-1].result.step:
                last = episodes[-1]
                expected = int(last.steps[-1].result.step) + 1
                if result.step != expected:
                    last.gaps.append(f'steps {expected}-{result.step - 1} missing')
                last.steps.append(record)
            elif not episodes and result.step == 1 and fresh_config is not None:
                cfg = _config_from_json(fresh_config.get('config')) or cfg
                seed = fresh_config.get('seed')
                fresh_config = None
                episodes.append(Episode(0, int(result.reset_id), cfg, seed, True, [record],
                                        reset_recorded=False))
            elif episodes or bag.damage:  # the reset of this step's episode was lost
                episodes.append(Episode(
                    len(episodes), int(result.reset_id), cfg, None, False, [record],
                    reset_recorded=False,
                    gaps=[f'its reset and the steps before step {result.step} missing']))
    _attribute_damage(bag, episodes)
    return episodes


def _attribute_damage(bag: Bag, episodes: list[Episode]) -> None:
    """Name each unreadable part of the file in the episodes its log-time range overlaps."""
    starts = [e.steps[0].log_time for e in episodes]
    for part in bag.damage:
        if part.start_time is None:
            continue  # no message was lost (e.g. a metadata record)
        for i, episode in enumerate(episodes):
            # An episode owns [its first message, the next episode's first); the first one also
            # what came before it, which may have been its own start.
            low = starts[i] if i else -math.inf
            high = starts[i + 1] if i + 1 < len(starts) else math.inf
            if part.start_time < high and part.end_time >= low:
                episode.unreadable.append(part)


def _config_from_json(value: Any) -> SimConfig | None:
    if value is None:
        return None
    if isinstance(value, str):
        value = json.loads(value)
    return SimConfig.from_dict(value)


# ---------------------------------------------------------------------- summary
def summary(path: str | os.PathLike, namespace: str | None = None) -> dict[str, Any]:
    """Episodes, returns, steps and duration of a recording.

    Args:
        path: The ``.mcap`` file.
        namespace: The chamber namespace; None = the only one.

    Returns:
        A JSON-ready dict.

    Raises:
        ReplayError: The file cannot be read.
    """
    with Bag(path) as bag:
        episodes = read_episodes(bag, namespace)
        meta = bag.metadata.get(METADATA_NAME, {})
        return {
            'path': str(bag.path),
            'size_bytes': bag.size_bytes,
            'files': [f.name for f in bag.files],
            'version': meta.get('version', ''),
            'seed': meta.get('seed', ''),
            'mode': meta.get('mode', ''),
            'duration_s': (bag.end_time - bag.start_time) / 1e9,
            'messages': {t: i.count for t, i in sorted(bag.topics.items())},
            'episodes': [{
                'index': e.index, 'reset_id': e.reset_id,
                'challenge': e.config.challenge if e.config else '',
                'setting': e.config.setting if e.config else '',
                'seed': e.seed, 'steps': e.n_steps, 'rejected': len(e.rejected),
                'return': e.episode_return,
                'success': bool(e.steps[-1].result.success), 'complete': e.done,
                'duration_s': e.duration_ns / 1e9, 'damaged': e.damaged,
            } for e in episodes],
            'total_steps': sum(e.n_steps for e in episodes),
            'unreadable': [{
                'offset': part.offset, 'end': part.end, 'what': part.what,
                'reason': part.reason, 'start_time_ns': part.start_time,
                'end_time_ns': part.end_time,
                'episodes': [e.index for e in episodes if part in e.unreadable],
            } for part in bag.damage],
        }


def format_summary(info: dict[str, Any]) -> str:
    files = f', {len(info["files"])} files' if len(info.get('files', ())) > 1 else ''
    lines = [f'{info["path"]}: {info["size_bytes"]} B{files}, {info["duration_s"]:.1f} s, '
             f'{len(info["episodes"])} episode(s), {info["total_steps"]} step(s), '
             f'version {info["version"] or "?"}, first seed {info["seed"] or "?"}, '
             f'{info["mode"] or "?"}',
             f'{"ep":>3} {"reset":>5} {"challenge":>10} {"setting":>7} {"seed":>12} '
             f'{"steps":>5} {"return":>9} {"success":>7} {"complete":>8} {"dur[s]":>7}']
    for e in info['episodes']:
        seed = '(cont.)' if e['seed'] is None else str(e['seed'])
        lines.append(f'{e["index"]:>3} {e["reset_id"]:>5} {e["challenge"]:>10} '
                     f'{e["setting"]:>7} {seed:>12} {e["steps"]:>5} {e["return"]:>9.4f} '
                     f'{str(e["success"]):>7} {str(e["complete"]):>8} '
                     f'{e["duration_s"]:>7.1f}')
    lines.append('messages: ' + ', '.join(f'{t} {n}' for t, n in info['messages'].items()))
    for part in info['unreadable']:
        touched = ', '.join(map(str, part['episodes'])) or 'none'
        lines.append(f'UNREADABLE {part["what"]} at bytes {part["offset"]}-{part["end"]} '
                     f'({part["reason"]}); skipped; episode(s) touched: {touched}')
    for e in info['episodes']:
        if e['damaged']:
            lines.append(f'episode {e["index"]} is incomplete: {"; ".join(e["damaged"])}')
    return '\n'.join(lines)
