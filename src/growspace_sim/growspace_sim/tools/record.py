"""``growspace-record``: record agent episodes in-process, or a running chamber's topics.

- ``growspace-record run OUT.mcap --challenge shape --episodes 3 --agent oracle --seed 7``
  runs the chamber node in process (``episode_runner``), which records every message it handles:
  lossless, deterministic, re-simulatable with ``growspace-replay check``.
- ``growspace-record subscribe OUT.mcap --namespace /growspace`` subscribes to a running
  chamber over rclpy until Ctrl-C, SIGTERM or ``--duration``. A subscriber can miss messages
  the node published before it matched; the node's own recording (its ``record_path``
  parameter) is the lossless one.

SIGINT and SIGTERM finish the file (summary and indexes) before exiting.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
import json
import logging
import os
import sys
import time
from typing import Any

from growspace_sim import arguments, recording
from growspace_sim.agents.evaluation import AGENTS, make_agent, play_episodes
from growspace_sim.core import task as tasks
from growspace_sim.core.config import SimConfig
from growspace_sim.node.episode_runner import EpisodeRunner
from growspace_sim.ros import convert, names, qos as ros_qos
from growspace_sim.ros.names import DEFAULT_NAMESPACE
from growspace_sim.ros.interface import TOPICS


def run(args: argparse.Namespace) -> int:
    """Record ``args.episodes`` episodes of an agent; returns the exit status."""
    cfg = SimConfig(challenge=args.challenge, setting=args.setting)
    with recording.stop_on_signals(), \
            recording.McapRecorder(args.out, overwrite=args.overwrite) as recorder:
        runner = EpisodeRunner(cfg, recorder, namespace=args.namespace, rate_hz=args.rate_hz)
        # The first reset starts the node (its first episode); later ones are ResetRequests.
        agent = make_agent(args.agent, runner, args.seed)
        period, next_tick = 1.0 / args.rate_hz, time.monotonic()

        def pace() -> None:
            nonlocal next_tick
            next_tick += period
            time.sleep(max(0.0, next_tick - time.monotonic()))
        for episode in range(args.episodes):
            seed = args.seed + episode
            played = play_episodes(runner, agent, [seed], on_step=pace if args.realtime else None)
            print(f'episode {episode}: seed {seed}, return {played.returns[0]:.4f}', flush=True)
        if runner.recording_error:
            print(f'growspace-record: error: {runner.recording_error}', file=sys.stderr)
            return 1
    return 0


def subscribe(args: argparse.Namespace) -> int:
    """Record a running chamber's topics over rclpy; returns the exit status."""
    from growspace_sim.node.presence import ChamberWatch
    from growspace_sim.node.rclpy_transport import RclpyTransport

    namespace = names.normalize_namespace(args.namespace)
    deadline = None if args.duration is None else time.monotonic() + args.duration
    count = 0
    with recording.stop_on_signals(), \
            recording.McapRecorder(args.out, overwrite=args.overwrite) as recorder:
        transport = RclpyTransport(f'growspace_recorder_{os.getpid()}', namespace,
                                   domain_id=args.domain_id)
        have_metadata = False

        def record(rel: str, channel: int) -> Callable[[Any, bytes], None]:
            def write(msg: Any, cdr: bytes) -> None:
                nonlocal count, have_metadata
                if rel == 'chamber/config' and not have_metadata:
                    have_metadata = _write_metadata(recorder, msg.data, namespace)
                now = time.time_ns()
                header = getattr(msg, 'header', None)
                sent = now if header is None else convert.to_ns(header.stamp)
                recorder.write(channel, cdr, now, sent)
                count += 1
            return write
        try:
            for _, rel, typename, qos in TOPICS:
                channel = recorder.add_channel(transport.resolve(rel), typename, qos)
                # keep_all on the reader: a slow disk must not make the middleware drop samples.
                reader_qos = ros_qos.QosProfile(history='keep_all', durability=qos.durability)
                transport.subscribe(typename, rel, reader_qos, record(rel, channel))
            watch = ChamberWatch(transport, 'growspace-record',
                                 lambda text: print(text, file=sys.stderr, flush=True))
            while deadline is None or time.monotonic() < deadline:
                transport.spin_once(0.05)
                if have_metadata:
                    watch.seen()
                watch.check()
        except KeyboardInterrupt:
            pass
        finally:
            transport.close()
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
    parser = arguments.Parser(prog='growspace-record', description=__doc__.split('\n')[0])
    sub = parser.add_subparsers(dest='command', required=True)
    p_run = sub.add_parser('run', help='run episodes in-process and record them')
    p_run.add_argument('out', type=arguments.new_file)
    p_run.add_argument('--challenge', type=arguments.checked(tasks.get), default='control',
                       help=f'one of {", ".join(tasks.names())}, or module:attribute of a Task '
                       'of your own')
    p_run.add_argument('--setting', default='easy', help='a setting of the challenge')
    p_run.add_argument('--episodes', type=arguments.integer(1), default=1)
    p_run.add_argument('--agent', choices=AGENTS, default='oracle')
    p_run.add_argument('--seed', type=arguments.SEED, default=0, help='episode i uses seed + i')
    p_run.add_argument('--rate-hz', type=arguments.number(0, low_open=True), default=10.0)
    p_run.add_argument('--realtime', action='store_true', help='pace steps at rate-hz')
    p_run.add_argument('--namespace', type=arguments.namespace, default=DEFAULT_NAMESPACE)
    p_run.add_argument('--overwrite', action='store_true')
    p_sub = sub.add_parser('subscribe', help="record a running chamber's topics over ROS 2")
    p_sub.add_argument('out', type=arguments.new_file)
    p_sub.add_argument('--namespace', type=arguments.namespace, default=DEFAULT_NAMESPACE)
    p_sub.add_argument('--duration', type=arguments.number(0, low_open=True),
                       help='seconds; default: until Ctrl-C')
    p_sub.add_argument('--domain-id', type=arguments.DOMAIN_ID, help='default: ROS_DOMAIN_ID')
    p_sub.add_argument('--overwrite', action='store_true')
    args = parser.parse_args(argv)
    if args.command == 'run':
        try:  # the setting's names depend on the challenge: checked together, before any file
            SimConfig(challenge=args.challenge, setting=args.setting)
        except ValueError as e:
            p_run.error(f'argument --setting: {e}')
    try:
        return run(args) if args.command == 'run' else subscribe(args)
    except (recording.RecordingError, ValueError) as e:  # a bad challenge, setting, file
        print(f'growspace-record: error: {e}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('growspace-record: interrupted; the recording was finished.', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
