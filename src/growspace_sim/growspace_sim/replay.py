"""Read GrowSpace recordings: summary, re-simulation check, GIF/MP4 export, republish, recovery.

``growspace-replay`` subcommands:
- ``info BAG``: episodes, returns, steps, duration, messages per topic;
- ``check BAG``: re-simulate every episode from the recorded config, seed and commands and
  report whether every image, plant state, applied light and reward is bit-identical (exit 0)
  or the first mismatch (exit 1);
- ``export BAG OUT.gif|OUT.mp4``: one episode's camera images, with a progress bar;
- ``play BAG``: republish the messages on their topics over rclpy, with the recorded timing or
  as fast as possible (``ros2 bag play`` where rosbag2 is not installed);
- ``recover BAG OUT``: copy the complete chunks of a file cut short by a crash.

Messages are read in file order, which is the order the node handled them in (the topics and
their order are ``node.interface``; the episode structure is in ``docs/recording.md``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
from pathlib import Path
import re
import sys
import time
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from growspace_sim import convert, recording
from growspace_sim.core.config import SimConfig
from growspace_sim.node.interface import TOPICS
from growspace_sim.ros import qos as ros_qos, types
from growspace_sim.simulation import Simulation

# Fields each topic's comparison covers: what the simulation decides, not the ids and stamps.
COMPARED = {
    'camera/image_raw': ('height', 'width', 'encoding', 'step', 'data'),
    'plant/state': ('step', 'node_x', 'node_z', 'parent', 'plant', 'tips', 'branch_count'),
    'light/state': ('mode', 'x', 'z', 'width', 'radius'),
    'step_result': ('step', 'reward', 'plant_rewards', 'terminated', 'truncated', 'success'),
}


class ReplayError(Exception):
    """Raised when a recording cannot be read or does not hold what the request needs."""


# ---------------------------------------------------------------------- reading
@dataclasses.dataclass(frozen=True)
class BagMessage:
    """One recorded message, still serialised."""

    topic: str
    typename: str
    log_time: int  # ns
    publish_time: int  # ns
    data: bytes  # CDR with encapsulation header

    def decode(self) -> Any:
        return types.deserialize(self.data, self.typename)


@dataclasses.dataclass(frozen=True)
class TopicInfo:
    topic: str
    typename: str
    qos: ros_qos.QosProfile
    type_hash: str
    count: int


class Bag:
    """A finished MCAP recording opened for reading (see ``recording.recover`` for broken ones).

    Args:
        path: The ``.mcap`` file.

    Raises:
        ReplayError: The file does not exist, is not MCAP, is not profile ``ros2``, or has no
            summary (cut short by a crash: the message says how to recover it).
    """

    def __init__(self, path: str | os.PathLike) -> None:
        from mcap.reader import SeekingReader

        self.path = Path(path)
        if not self.path.exists():
            raise ReplayError(f'No recording at {self.path}: the file does not exist.')
        if self.path.is_dir():
            raise ReplayError(f'{self.path} is a directory; give the path of a .mcap file.')
        try:
            self._stream = open(self.path, 'rb')
        except OSError as e:
            raise ReplayError(f'Cannot open {self.path}: {e.strerror or e}') from e
        try:
            self._reader = SeekingReader(self._stream, validate_crcs=True)
            header = self._reader.get_header()
        except Exception as e:  # noqa: BLE001 - InvalidMagic, EndOfFile, struct errors
            self.close()
            raise ReplayError(f'{self.path} is not an MCAP file ({type(e).__name__}).') from e
        if header.profile != recording.PROFILE:
            self.close()
            raise ReplayError(f'{self.path} has MCAP profile {header.profile!r}, expected '
                              f'{recording.PROFILE!r} (a ROS 2 recording).')
        try:
            summary = self._reader.get_summary()
            if summary is None:
                raise ValueError('no summary section')
        except Exception as e:  # noqa: BLE001 - truncated footer or summary
            self.close()
            raise ReplayError(
                f'{self.path} is incomplete ({e or type(e).__name__}): the recording was cut '
                f'short, e.g. by a hard kill. Copy its complete chunks into a new file with '
                f'`growspace-replay recover {self.path} FIXED.mcap`.') from e
        self.summary = summary
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        self.topics: dict[str, TopicInfo] = {}
        self._channels: dict[int, TopicInfo] = {}
        for cid, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            if schema is None or channel.message_encoding != 'cdr':
                continue
            info = TopicInfo(channel.topic, schema.name,
                             parse_qos(channel.metadata.get('offered_qos_profiles', '')),
                             channel.metadata.get('topic_type_hash', ''), counts.get(cid, 0))
            self._channels[cid] = info
            self.topics[channel.topic] = info
        self.metadata = {m.name: dict(m.metadata) for m in self._reader.iter_metadata()}

    @property
    def start_time(self) -> int:
        return self.summary.statistics.message_start_time if self.summary.statistics else 0

    @property
    def end_time(self) -> int:
        return self.summary.statistics.message_end_time if self.summary.statistics else 0

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
        """Messages in file order (the order they were recorded in).

        Args:
            topics: Only these topics; None = all.
        """
        wanted = None if topics is None else set(topics)
        for _, channel, message in self._reader.iter_messages(
                topics=None if wanted is None else list(wanted), log_time_order=False):
            info = self._channels.get(channel.id)
            if info is None:
                continue
            yield BagMessage(info.topic, info.typename, message.log_time,
                             message.publish_time, message.data)

    def chamber_topics(self, namespace: str | None = None) -> dict[str, str]:
        """Map the node's relative topic names to the recorded ones.

        Args:
            namespace: The chamber namespace; None = the only chamber in the file.

        Returns:
            Relative name (``step_result``) -> recorded name (``/growspace/step_result``).

        Raises:
            ReplayError: No chamber, or several and no namespace given.
        """
        candidates = sorted(t[:-len('/step_result')] or '/' for t, i in self.topics.items()
                            if t.endswith('/step_result') and i.typename == types.STEP_RESULT)
        if namespace is not None:
            namespace = '/' + namespace.strip('/') if namespace.strip('/') else '/'
            if namespace not in candidates:
                raise ReplayError(f'{self.path} has no chamber in namespace {namespace!r}; '
                                  f'found {candidates or "none"}.')
        elif len(candidates) == 1:
            namespace = candidates[0]
        elif not candidates:
            raise ReplayError(f'{self.path} holds no {types.STEP_RESULT} topic: not a GrowSpace '
                              f'chamber recording.')
        else:
            raise ReplayError(f'{self.path} holds several chambers {candidates}; pick one with '
                              f'--namespace.')
        prefix = '' if namespace == '/' else namespace
        out = {}
        for topic in TOPICS:
            rel = topic.name
            full = rel if rel.startswith('/') else f'{prefix}/{rel}'
            if full in self.topics:
                out[rel] = full
        return out

    def close(self) -> None:
        self._stream.close()

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def parse_qos(text: str) -> ros_qos.QosProfile:
    """The first profile of an ``offered_qos_profiles`` YAML string (v8 ints or v9 strings).

    Unknown or missing values fall back to the ROS default profile.
    """
    def value(key: str) -> str | None:
        match = re.search(rf'^\s*-?\s*{key}:\s*(\S+)\s*$', text, re.MULTILINE)
        return match.group(1) if match else None

    enums = {  # rosbag2 v8 wrote rmw enum integers
        'history': {'1': 'keep_last', '2': 'keep_all'},
        'reliability': {'1': 'reliable', '2': 'best_effort'},
        'durability': {'1': 'transient_local', '2': 'volatile'},
    }
    fields: dict[str, Any] = {}
    for key, table in enums.items():
        raw = value(key)
        raw = table.get(raw, raw)
        if raw in table.values():
            fields[key] = raw
    depth = value('depth')
    if depth and depth.isdigit() and int(depth) > 0:
        fields['depth'] = int(depth)
    try:
        return ros_qos.QosProfile(**fields)
    except ValueError:
        return ros_qos.DEFAULT


# ---------------------------------------------------------------------- episodes
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

    @property
    def n_steps(self) -> int:
        return len(self.steps) - 1

    @property
    def episode_return(self) -> float:
        return float(sum(s.result.reward for s in self.steps[1:]))

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
    command or reset, a command after the episode's end); it goes to ``Episode.rejected``. Steps
    recorded before the first reset (a recorder that joined a running chamber) are dropped:
    without their reset they cannot be re-simulated.

    Args:
        bag: The open recording.
        namespace: The chamber namespace; None = the only one.

    Returns:
        The episodes in recorded order.
    """
    topics = bag.chamber_topics(namespace)
    rel_of = {full: rel for rel, full in topics.items()}
    meta = bag.metadata.get(recording.METADATA_NAME, {})
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
        if rel == 'reset':
            request = msg.decode()
            requests[int(request.reset_id)] = request
        elif rel == 'chamber/config':
            try:
                fresh_config = json.loads(msg.decode().data)
            except ValueError:
                fresh_config = None
        elif rel == 'light/command':
            commands.append(msg.decode())
        elif rel in COMPARED and rel != 'step_result':
            outputs[rel] = msg
        elif rel == 'step_result':
            result = msg.decode()
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
            elif episodes:
                episodes[-1].steps.append(record)
    return episodes


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
        meta = bag.metadata.get(recording.METADATA_NAME, {})
        return {
            'path': str(bag.path),
            'size_bytes': bag.path.stat().st_size,
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
                'duration_s': e.duration_ns / 1e9,
            } for e in episodes],
            'total_steps': sum(e.n_steps for e in episodes),
        }


def format_summary(info: dict[str, Any]) -> str:
    lines = [f'{info["path"]}: {info["size_bytes"]} B, {info["duration_s"]:.1f} s, '
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
    return '\n'.join(lines)


# ---------------------------------------------------------------------- re-simulation
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

    @property
    def ok(self) -> bool:
        return self.mismatch is None and self.episodes > 0


def resimulate(path: str | os.PathLike, namespace: str | None = None, *,
               digit_source: str | None = None,
               progress: Callable[[int, int], None] | None = None) -> ResimReport:
    """Re-run every recorded episode and compare it with the recording, bit for bit.

    Per episode: the recorded config and seed reset a ``Simulation`` (a config change builds a
    new one that keeps the random stream, as the node does); per step, the recorded light
    commands are applied through ``convert.apply_command`` (in lockstep only the one whose
    step_id the result answers; in realtime mode the latest one) and the chamber steps.
    Images (bytes), plant states (node arrays, tips, counts), applied lights and rewards must
    equal the recorded ones exactly. Stops at the first mismatch.

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
        topics = bag.chamber_topics(namespace)
        for rel, full in topics.items():
            recorded_hash = bag.topics[full].type_hash
            if recorded_hash and recorded_hash != types.type_hash(bag.topics[full].typename):
                report.warnings.append(f'{full}: recorded type hash {recorded_hash} differs '
                                       f'from this version\'s message definition.')
        meta = bag.metadata.get(recording.METADATA_NAME, {})
        source = digit_source or meta.get('digit_source') or 'auto'
        lockstep = meta.get('mode') != 'realtime'
        episodes = read_episodes(bag, namespace)
        if not episodes:
            raise ReplayError(f'{bag.path} holds no episode start (StepResult with step 0).')
        sim: Simulation | None = None
        for episode in episodes:
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
                current = recording.digit_fingerprint(sim)
                if fingerprint and current and fingerprint != current:
                    report.warnings.append(f'the shape digits differ from the recorded ones '
                                           f'(source {source!r}); images will not match.')
            outcome = sim.reset(seed=episode.seed)
            mismatch = _compare_step(sim, outcome, episode, episode.steps[0], report)
            for record in episode.steps[1:]:
                if mismatch is not None:
                    break
                _apply_command(sim, record, lockstep)
                outcome = sim.step()
                mismatch = _compare_step(sim, outcome, episode, record, report)
                report.steps += 1
            report.episodes += 1
            if progress is not None:
                progress(report.episodes, len(episodes))
            if mismatch is not None:
                report.mismatch = mismatch
                break
    return report


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


# ---------------------------------------------------------------------- export
def _progress_bar(label: str, total: int, stream: Any = None) -> Callable[[int], None]:
    """A one-line text progress bar (tqdm is not a dependency)."""
    stream = stream or sys.stderr
    width = 30

    interactive = getattr(stream, 'isatty', lambda: False)()
    shown = [-1]

    def update(done: int) -> None:
        filled = int(width * done / max(total, 1))
        if (not interactive and done < total) or (filled == shown[0] and done < total):
            return  # redraw only when the bar grows; a log file gets the last line only
        shown[0] = filled
        stream.write(f'\r{label} [{"#" * filled}{"." * (width - filled)}] {done}/{total}')
        if done >= total:
            stream.write('\n')
        stream.flush()
    return update


def export_episode(path: str | os.PathLike, out: str | os.PathLike, *, episode: int = 0,
                   fps: float | None = None, scale: int = 4, namespace: str | None = None,
                   progress: bool = True, overwrite: bool = False) -> int:
    """Write one episode's camera images as an animated GIF or an MP4 video.

    Args:
        path: The recording.
        out: ``.gif`` (Pillow) or ``.mp4`` (OpenCV's bundled FFmpeg, codec mp4v).
        episode: 0-based episode index (negative counts from the end).
        fps: Frames per second; None = the recorded rate (default 10).
        scale: Integer upscaling (nearest neighbour) so 84 px frames are visible.
        namespace: The chamber namespace; None = the only one.
        progress: Show a progress bar on stderr.
        overwrite: Replace ``out`` if it exists.

    Returns:
        The number of frames written.

    Raises:
        ReplayError: Unreadable recording, no such episode, an existing output, an unknown
            extension, or no MP4 encoder.
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in ('.gif', '.mp4'):
        raise ReplayError(f'Cannot export to {out}: use a .gif or .mp4 file name.')
    if out.exists() and not overwrite:
        raise ReplayError(f'{out} exists already, not overwriting.')
    if scale < 1:
        raise ReplayError(f'scale must be >= 1, got {scale}.')
    with Bag(path) as bag:
        episodes = read_episodes(bag, namespace)
        if not -len(episodes) <= episode < len(episodes):
            raise ReplayError(f'{bag.path} has {len(episodes)} episode(s); episode {episode} '
                              f'does not exist.')
        chosen = episodes[episode]
        rate = float(bag.metadata.get(recording.METADATA_NAME, {}).get('rate_hz') or 10.0)
        fps = fps or rate
        frames = []
        for record in chosen.steps:
            image = record.outputs.get('camera/image_raw')
            if image is not None:
                frame = convert.image_from_msg(image.decode())
                frames.append(np.repeat(np.repeat(frame, scale, axis=0), scale, axis=1))
    if not frames:
        raise ReplayError(f'Episode {episode} of {path} has no camera images.')
    update = _progress_bar(f'export {out.name}', len(frames)) if progress else (lambda n: None)
    if suffix == '.gif':
        from PIL import Image

        images = []
        for i, frame in enumerate(frames, 1):
            images.append(Image.fromarray(frame))
            update(i)
        images[0].save(out, save_all=True, append_images=images[1:],
                       duration=round(1000 / fps), loop=0)
    else:
        import cv2

        h, w = frames[0].shape[:2]
        writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*'mp4v'), fps, (w, h))
        if not writer.isOpened():
            raise ReplayError(f'No MP4 encoder available to OpenCV for {out}; export a .gif.')
        try:
            for i, frame in enumerate(frames, 1):
                writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))  # OpenCV writes BGR
                update(i)
        finally:
            writer.release()
    return len(frames)


# ---------------------------------------------------------------------- republish
def play(path: str | os.PathLike, *, rate: float | None = 1.0, topics: Iterable[str] | None = None,
         domain_id: int | None = None, wait_for_subscribers_s: float = 0.0,
         log: Callable[[str], None] | None = None) -> int:
    """Republish a recording on its topics over rclpy (``ros2 bag play`` without rosbag2).

    On a machine with ROS 2, ``ros2 bag play BAG`` does the same through rmw.

    Args:
        path: The recording.
        rate: Speed factor on the recorded log times (1.0 = original timing); None = as fast
            as possible.
        topics: Only these recorded topic names; None = all.
        domain_id: ROS domain; None = ROS_DOMAIN_ID.
        wait_for_subscribers_s: Before playing, wait up to this long for every publisher to
            match a subscriber.
        log: Where progress lines go (None = quiet).

    Returns:
        The number of messages published.

    Raises:
        ReplayError: The file cannot be read or the rate is not positive.
    """
    if rate is not None and not rate > 0:
        raise ReplayError(f'rate must be > 0, got {rate}.')
    from growspace_sim.node.rclpy_transport import RclpyTransport

    count = 0
    with Bag(path) as bag:
        transport = RclpyTransport(f'growspace_replay_{os.getpid()}', domain_id=domain_id)
        try:
            wanted = set(bag.topics) if topics is None else set(topics) & set(bag.topics)
            publishers = {t: transport.raw_publisher(bag.topics[t].typename, t,
                                                     bag.topics[t].qos)
                          for t in sorted(wanted)}
            deadline = time.monotonic() + wait_for_subscribers_s
            while time.monotonic() < deadline and not all(map(transport.matched, publishers)):
                transport.spin_once(0.02)
            start_wall = time.monotonic()
            first_log: int | None = None
            for msg in bag.messages(wanted):
                if rate is not None:
                    first_log = msg.log_time if first_log is None else first_log
                    delay = (start_wall + (msg.log_time - first_log) / 1e9 / rate
                             - time.monotonic())
                    if delay > 0:
                        time.sleep(delay)
                publishers[msg.topic](msg.data)
                count += 1
                if log is not None and count % 500 == 0:
                    log(f'published {count} messages')
            transport.flush(2.0)
        finally:
            transport.close()
    return count


# ---------------------------------------------------------------------- CLI
def main(argv: list[str] | None = None) -> int:
    """``growspace-replay`` entry point; returns the exit status (0 ok, 1 mismatch, 2 error)."""
    parser = argparse.ArgumentParser(prog='growspace-replay', description=__doc__.split('\n')[0])
    sub = parser.add_subparsers(dest='command', required=True)
    p_info = sub.add_parser('info', help='episodes, returns, steps and duration')
    p_info.add_argument('bag')
    p_info.add_argument('--namespace')
    p_info.add_argument('--json', action='store_true', help='print JSON instead of a table')
    p_check = sub.add_parser('check', help='re-simulate and compare bit for bit')
    p_check.add_argument('bag')
    p_check.add_argument('--namespace')
    p_check.add_argument('--digit-source', help="override the recorded one ('auto', 'idx', ...)")
    p_export = sub.add_parser('export', help='one episode to GIF or MP4')
    p_export.add_argument('bag')
    p_export.add_argument('out', help='.gif or .mp4')
    p_export.add_argument('--episode', type=int, default=0, help='0-based; -1 = last')
    p_export.add_argument('--fps', type=float, help='default: the recorded rate')
    p_export.add_argument('--scale', type=int, default=4)
    p_export.add_argument('--namespace')
    p_export.add_argument('--overwrite', action='store_true')
    p_play = sub.add_parser('play', help='republish on the topics over ROS 2')
    p_play.add_argument('bag')
    speed = p_play.add_mutually_exclusive_group()
    speed.add_argument('--rate', type=float, default=1.0, help='speed factor (1 = original)')
    speed.add_argument('--fast', action='store_true', help='as fast as possible')
    p_play.add_argument('--topics', nargs='+', help='recorded topic names to publish')
    p_play.add_argument('--domain-id', type=int, help='default: ROS_DOMAIN_ID')
    p_play.add_argument('--wait', type=float, default=1.0,
                        help='seconds to wait for subscribers first')
    p_recover = sub.add_parser('recover', help='copy the complete chunks of a damaged file')
    p_recover.add_argument('bag')
    p_recover.add_argument('out')
    args = parser.parse_args(argv)
    try:
        if args.command == 'info':
            info = summary(args.bag, args.namespace)
            print(json.dumps(info, indent=2) if args.json else format_summary(info))
        elif args.command == 'check':
            bars: dict[int, Callable[[int], None]] = {}
            report = resimulate(
                args.bag, args.namespace, digit_source=args.digit_source,
                progress=lambda done, total: bars.setdefault(
                    total, _progress_bar('check', total))(done))
            for warning in report.warnings:
                print(f'warning: {warning}', file=sys.stderr)
            if not report.ok:
                print(f'MISMATCH at {report.mismatch} (after {report.steps} matching steps)')
                return 1
            print(f'REPRODUCED: {report.episodes} episode(s), {report.steps} step(s), '
                  f'{report.messages_compared} messages: every image, plant state, applied '
                  f'light and reward is bit-identical.')
        elif args.command == 'export':
            n = export_episode(args.bag, args.out, episode=args.episode, fps=args.fps,
                               scale=args.scale, namespace=args.namespace,
                               overwrite=args.overwrite)
            print(f'wrote {n} frames to {args.out}')
        elif args.command == 'play':
            with recording.stop_on_signals():
                n = play(args.bag, rate=None if args.fast else args.rate, topics=args.topics,
                         domain_id=args.domain_id, wait_for_subscribers_s=args.wait,
                         log=lambda line: print(line, file=sys.stderr))
            print(f'published {n} messages')
        elif args.command == 'recover':
            rep = recording.recover(args.bag, args.out)
            state = 'file was complete' if rep.complete else f'stopped at byte {rep.stopped_at}' \
                f'{": " + rep.reason if rep.reason else ""}'
            print(f'recovered {rep.messages} messages from {rep.chunks} chunk(s) and '
                  f'{rep.metadata} metadata record(s) into {args.out} ({state})')
    except (ReplayError, recording.RecordingError, ValueError) as e:
        print(f'growspace-replay: error: {e}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == '__main__':
    sys.exit(main())
