"""``growspace-record``: record agent episodes in-process, or a running chamber's topics.

- ``growspace-record run OUT.mcap --challenge shape --episodes 3 --agent oracle --seed 7``
  runs the chamber node in process (``episode_runner``), which records every message it handles:
  lossless, deterministic, re-simulatable with ``growspace-replay check``.
- ``growspace-record subscribe OUT.mcap --namespace /growspace`` subscribes to a running
  chamber over Cyclone DDS (loopback unless CYCLONEDDS_URI is set) until Ctrl-C, SIGTERM or
  ``--duration``. A subscriber can miss messages the node published before it matched; the
  node's own recording (its ``record_path`` parameter) is the lossless one.

SIGINT and SIGTERM finish the file (summary and indexes) before exiting.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time

from growspace_sim import recording
from growspace_sim.core.config import CHALLENGES, SETTINGS, SimConfig
from growspace_sim.episode_runner import DEFAULT_NAMESPACE, EpisodeRunner
from growspace_sim.node.interface import TOPICS
from growspace_sim.node.params import DEFAULT_NODE_NAME
from growspace_sim.ros import names, types


def run(args: argparse.Namespace) -> int:
    """Record ``args.episodes`` episodes of an agent; returns the exit status."""
    from growspace_sim.agents import OracleAgent, RandomAgent

    cfg = SimConfig(challenge=args.challenge, setting=args.setting)
    with recording.stop_on_signals(), \
            recording.McapRecorder(args.out, overwrite=args.overwrite) as recorder:
        runner = EpisodeRunner(cfg, recorder, namespace=args.namespace, rate_hz=args.rate_hz)
        if args.agent == 'oracle':
            policy = OracleAgent().act
        else:
            import gymnasium as gym

            policy = RandomAgent(gym.spaces.Discrete(runner.n_actions), args.seed).act
        period = 1.0 / args.rate_hz
        next_tick = time.monotonic()
        for episode in range(args.episodes):
            # The first episode is the node's start; later ones begin with a ResetRequest.
            runner.reset(args.seed + episode)
            ret = 0.0
            while True:
                if args.realtime:
                    next_tick += period
                    time.sleep(max(0.0, next_tick - time.monotonic()))
                outcome = runner.step(policy(runner.observation, runner))
                ret += outcome.reward
                if outcome.truncated:
                    break
            print(f'episode {episode}: seed {args.seed + episode}, return {ret:.4f}',
                  flush=True)
        if runner.recording_error:
            print(f'growspace-record: error: {runner.recording_error}', file=sys.stderr)
            return 1
    return 0


def subscribe(args: argparse.Namespace) -> int:
    """Record a running chamber's topics over DDS; returns the exit status."""
    from growspace_sim.ros import dds, qos as ros_qos

    dds.ensure_loopback_config()
    namespace = names.normalize_namespace(args.namespace)
    rank = {topic.name: i for i, topic in enumerate(TOPICS)}  # the node's handling order
    deadline = None if args.duration is None else time.monotonic() + args.duration
    count = 0
    with recording.stop_on_signals(), \
            recording.McapRecorder(args.out, overwrite=args.overwrite) as recorder, \
            dds.DdsContext('growspace_recorder', '/', args.domain_id) as ctx:
        subs, channels = [], {}
        for _, rel, typename, qos in TOPICS:
            topic = names.resolve_topic(rel, DEFAULT_NODE_NAME, namespace)
            # keep_all on the reader: a slow disk must not make DDS drop samples.
            reader_qos = ros_qos.QosProfile(history='keep_all', durability=qos.durability)
            subs.append((rel, ctx.create_subscription(typename, topic, reader_qos)))
            channels[rel] = recorder.add_channel(topic, typename, qos)
        have_metadata = False
        try:
            while deadline is None or time.monotonic() < deadline:
                subs[-1][1].wait(0.001)
                batch = []
                for rel, sub in subs:
                    for data, msg in sub.take(256):
                        if isinstance(msg, types.CdrError):
                            continue
                        batch.append((rank[rel], rel, data, msg))
                now = time.time_ns()
                for _, rel, data, msg in sorted(batch, key=lambda item: item[0]):
                    if rel == 'chamber/config' and not have_metadata:
                        have_metadata = _write_metadata(recorder, msg.data, namespace)
                    header = getattr(msg, 'header', None)
                    sent = now if header is None else (
                        int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec))
                    recorder.write(channels[rel], data, now, sent)
                    count += 1
        except KeyboardInterrupt:
            pass
    print(f'recorded {count} messages to {args.out}')
    return 0


def _write_metadata(recorder: recording.McapRecorder, text: str, namespace: str) -> bool:
    try:
        payload = json.loads(text)
        cfg = SimConfig.from_dict(payload['config'])
    except (ValueError, KeyError, TypeError):
        return False
    recorder.add_metadata(recording.METADATA_NAME, recording.growspace_metadata(
        cfg, payload.get('seed'), namespace=namespace, frame_id=payload.get('frame_id', 'chamber'),
        rate_hz=float(payload.get('rate_hz', 10.0)), lockstep=payload.get('mode') != 'realtime',
        digit_source=payload.get('digit_source', 'auto')))
    return True


def main(argv: list[str] | None = None) -> int:
    """``growspace-record`` entry point."""
    logging.basicConfig(level=logging.WARNING, format='%(levelname)s: %(message)s')
    parser = argparse.ArgumentParser(prog='growspace-record', description=__doc__.split('\n')[0])
    sub = parser.add_subparsers(dest='command', required=True)
    p_run = sub.add_parser('run', help='run episodes in-process and record them')
    p_run.add_argument('out')
    p_run.add_argument('--challenge', choices=CHALLENGES, default='control')
    p_run.add_argument('--setting', choices=SETTINGS, default='easy')
    p_run.add_argument('--episodes', type=int, default=1)
    p_run.add_argument('--agent', choices=('oracle', 'random'), default='oracle')
    p_run.add_argument('--seed', type=int, default=0, help='episode i uses seed + i')
    p_run.add_argument('--rate-hz', type=float, default=10.0)
    p_run.add_argument('--realtime', action='store_true', help='pace steps at rate-hz')
    p_run.add_argument('--namespace', default=DEFAULT_NAMESPACE)
    p_run.add_argument('--overwrite', action='store_true')
    p_sub = sub.add_parser('subscribe', help="record a running chamber's topics over DDS")
    p_sub.add_argument('out')
    p_sub.add_argument('--namespace', default=DEFAULT_NAMESPACE)
    p_sub.add_argument('--duration', type=float, help='seconds; default: until Ctrl-C')
    p_sub.add_argument('--domain-id', type=int, help='default: ROS_DOMAIN_ID')
    p_sub.add_argument('--overwrite', action='store_true')
    args = parser.parse_args(argv)
    try:
        return run(args) if args.command == 'run' else subscribe(args)
    except recording.RecordingError as e:
        print(f'growspace-record: error: {e}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('growspace-record: interrupted; the recording was finished.', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
