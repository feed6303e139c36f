"""``growspace-replay``: info, check, export, play, compare and recover from the command line."""

from __future__ import annotations

import argparse
import json
import sys

from tqdm import tqdm

from growspace_sim import arguments, recording
from growspace_sim.digits import SOURCES as DIGIT_SOURCES
from growspace_sim.replay.bag import ReplayError
from growspace_sim.replay.compare import compare, format_comparison
from growspace_sim.replay.episodes import format_summary, summary
from growspace_sim.replay.export import export_episode, FPS_RANGE, SCALE_RANGE
from growspace_sim.replay.play import play, PLAY_WAIT_S, play_steps
from growspace_sim.replay.resim import resimulate


def build_parser() -> argparse.ArgumentParser:
    """The ``growspace-replay`` command line (the tests parse the README's lines with it)."""
    parser = arguments.Parser(
        prog='growspace-replay', description=__doc__.split('\n')[0],
        epilog="The photos of a rig's recording (gantry_node with camera_node): "
               '`growspace-camera resegment IN.mcap OUT.mcap --set NAME=VALUE` measures them '
               'again with other settings into a new recording, `growspace-camera export BAG '
               'DIR` draws what the camera saw on each (docs/recording.md).')
    sub = parser.add_subparsers(dest='command', required=True)
    p_info = sub.add_parser('info', help='episodes, returns, steps and duration')
    p_info.add_argument('bag', type=arguments.recording)
    p_info.add_argument('--namespace', type=arguments.namespace)
    p_info.add_argument('--json', action='store_true', help='print JSON instead of a table')
    p_check = sub.add_parser('check', help='re-simulate and compare bit for bit')
    p_check.add_argument('bag', type=arguments.recording)
    p_check.add_argument('--namespace', type=arguments.namespace)
    p_check.add_argument('--digit-source', choices=DIGIT_SOURCES,
                         help='override the recorded one')
    p_export = sub.add_parser('export', help='one episode to GIF or MP4; with --view, a copy '
                              'of the recording with the view added')
    p_export.add_argument('bag', type=arguments.recording)
    p_export.add_argument('out', type=arguments.new_file, help='.gif or .mp4; .mcap with --view')
    p_export.add_argument('--view', action='store_true',
                          help='write OUT.mcap: every message, plus plant/markers and '
                               'camera/image_view after each step_result (as view_node)')
    p_export.add_argument('--view-size', type=arguments.integer(16, 4096), default=512,
                          help='view image width [px], 16..4096 (default 512)')
    p_export.add_argument('--episode', type=int, default=0, help='0-based; -1 = last')
    p_export.add_argument('--fps', type=arguments.number(*FPS_RANGE),
                          help=f'frames per second, {FPS_RANGE[0]}..{FPS_RANGE[1]} '
                               f'(default: the recorded rate, brought into that range)')
    p_export.add_argument('--scale', type=arguments.integer(*SCALE_RANGE), default=4,
                          help=f'upscaling of each frame, {SCALE_RANGE[0]}..{SCALE_RANGE[1]} '
                               f'(default 4)')
    p_export.add_argument('--namespace', type=arguments.namespace)
    p_export.add_argument('--overwrite', action='store_true')
    p_play = sub.add_parser('play', help='republish on the topics over ROS 2; with '
                            '--step-period, step by step onto a lockstep node (the gantry)')
    p_play.add_argument('bag', type=arguments.recording)
    speed = p_play.add_mutually_exclusive_group()
    speed.add_argument('--rate', type=arguments.number(0, low_open=True), default=1.0,
                       help='speed factor (1 = original)')
    speed.add_argument('--fast', action='store_true', help='as fast as possible')
    speed.add_argument('--step-period', type=arguments.number(0), metavar='SECONDS',
                       help="step by step onto a lockstep node: each episode's reset, then "
                            'each command once the previous step_result came, at least SECONDS '
                            'apart (0: as fast as the node answers; 3600: a real plant on the '
                            'LED gantry)')
    p_play.add_argument('--topics', '--only', nargs='+',
                        help='recorded topic names to publish, e.g. /growspace/light/command '
                             '(not with --step-period: it sends resets and commands)')
    p_play.add_argument('--domain-id', type=arguments.DOMAIN_ID, help='default: ROS_DOMAIN_ID')
    p_play.add_argument('--wait', type=arguments.number(0),
                        help='seconds to wait for subscribers first (default 10; play goes on '
                             'once the readers matched)')
    steps = p_play.add_argument_group('step by step (--step-period)')
    steps.add_argument('--episode', type=int, help='only this episode (0-based, -1 = last)')
    steps.add_argument('--start-step', type=arguments.integer(1), default=1, metavar='STEP_ID',
                       help='the first step_id to play; the light is placed where the '
                            'recording had it before')
    steps.add_argument('--stop-step', type=arguments.integer(1), metavar='STEP_ID',
                       help='the last step_id')
    steps.add_argument('--keep-going', action='store_true',
                       help='go on after a step that fails on the node (default: stop)')
    steps.add_argument('--step-timeout', type=arguments.number(0, low_open=True), default=600.0,
                       metavar='SECONDS',
                       help='give up when a step has no step_result for this long')
    steps.add_argument('--namespace', type=arguments.namespace,
                       help='the chamber namespace in the recording')
    p_compare = sub.add_parser('compare', help='applied light of B against A, step by step '
                                               '(e.g. a simulated run and its gantry replay)')
    p_compare.add_argument('a', type=arguments.recording, help='the reference recording')
    p_compare.add_argument('b', type=arguments.recording,
                           help='the recording to compare with it')
    p_compare.add_argument('--namespace-a', type=arguments.namespace)
    p_compare.add_argument('--namespace-b', type=arguments.namespace)
    p_compare.add_argument('--tolerance-mm', type=arguments.number(0),
                           help='exit 1 if any field of B is farther than this from A')
    p_recover = sub.add_parser('recover', help='copy the readable chunks of a damaged file '
                               'into OUT; a split recording directory: its last file, in place')
    p_recover.add_argument('bag', type=arguments.recording)
    p_recover.add_argument('out', nargs='?', type=arguments.new_file)
    return parser


def main(argv: list[str] | None = None) -> int:
    """``growspace-replay`` entry point; returns the exit status (0 ok, 1 mismatch or a failed
    step, 2 error)."""
    parser = build_parser()
    args = parser.parse_args(argv)

    def warn(line: str) -> None:
        print(f'warning: {line}', file=sys.stderr)

    try:
        if args.command == 'info':
            info = summary(args.bag, args.namespace)
            print(json.dumps(info, indent=2) if args.json else format_summary(info))
        elif args.command == 'check':
            bars: list[tqdm] = []  # drawn once there is progress: not before an error

            def progress(done: int, total: int) -> None:
                if not bars:
                    bars.append(tqdm(desc='check', unit='episode', total=total))
                bars[0].total = total
                bars[0].update(done - bars[0].n)
            try:
                report = resimulate(args.bag, args.namespace, digit_source=args.digit_source,
                                    progress=progress)
            finally:
                for bar in bars:
                    bar.close()
            for warning in report.warnings:
                warn(warning)
            for part in report.unreadable:
                warn(f'skipped unreadable {part}')
            if report.mismatch is not None:
                print(f'MISMATCH at {report.mismatch} (after {report.steps} matching steps)')
                return 1
            if report.unverified:
                print(f'NOT VERIFIED: {len(report.unverified)} episode(s) could not be checked '
                      f'(unreadable parts of the file); {report.episodes} other episode(s), '
                      f'{report.steps} step(s) are bit-identical.')
                for line in report.unverified:
                    print(f'  {line}')
                return 1
            print(f'REPRODUCED: {report.episodes} episode(s), {report.steps} step(s), '
                  f'{report.messages_compared} messages: every image, plant state, applied '
                  f'light and reward is bit-identical.')
        elif args.command == 'export' and args.view:
            from growspace_sim.replay.export_view import export_with_view

            n = export_with_view(args.bag, args.out, namespace=args.namespace,
                                 view_size=args.view_size, overwrite=args.overwrite,
                                 warn=warn)
            print(f'wrote {args.out} with {n} view frames (plant/markers, camera/image_view)')
        elif args.command == 'export':
            n = export_episode(args.bag, args.out, episode=args.episode, fps=args.fps,
                               scale=args.scale, namespace=args.namespace,
                               overwrite=args.overwrite, warn=warn)
            print(f'wrote {n} frames to {args.out}')
        elif args.command == 'play':
            return _play(parser, args)
        elif args.command == 'compare':
            result = compare(args.a, args.b, namespace_a=args.namespace_a,
                             namespace_b=args.namespace_b)
            print(format_comparison(result))
            if result.steps == 0:
                print('growspace-replay: error: no step of A and B could be compared',
                      file=sys.stderr)
                return 1
            if args.tolerance_mm is not None and not result.within(args.tolerance_mm / 1e3):
                print(f'OUT OF TOLERANCE: a field differs by more than {args.tolerance_mm} mm')
                return 1
        elif args.command == 'recover' and recording.is_split_recording(args.bag):
            if args.out is not None:
                parser.error(f'out = {args.out!r}: a split recording ({args.bag}) is repaired '
                             f'in place; give no OUT.')
            fixed = recording.repair(args.bag)
            if fixed.damaged is None:
                print(f'{args.bag}: every file is complete; nothing to recover')
            elif fixed.path is None:
                print(f'{args.bag}: moved unreadable {fixed.damaged.name} aside ({fixed.reason})')
            else:
                print(f'recovered {fixed.messages} messages into {fixed.path} ({fixed.reason}); '
                      f'the damaged original is {fixed.damaged}')
        elif args.command == 'recover':
            if args.out is None:
                parser.error(f'out: required for a single file ({args.bag}); only a split '
                             f'recording directory is repaired in place.')
            rep = recording.recover(args.bag, args.out)
            state = 'file was complete' if rep.complete else f'stopped at byte {rep.stopped_at}' \
                f'{": " + rep.reason if rep.reason else ""}'
            print(f'recovered {rep.messages} messages from {rep.chunks} chunk(s) and '
                  f'{rep.metadata} metadata record(s) into {args.out} ({state})')
            for part in rep.skipped:
                print(f'skipped unreadable {part}')
    except (ReplayError, recording.RecordingError, ValueError) as e:
        print(f'growspace-replay: error: {e}', file=sys.stderr)
        return 2
    except OSError as e:
        print(f'growspace-replay: error: {e.strerror or e}'
              f'{f" ({e.filename})" if e.filename else ""}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    return 0


def _play(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)
    stepwise = args.step_period is not None
    step_options = [name for name, value in (
        ('--episode', args.episode is not None), ('--start-step', args.start_step != 1),
        ('--stop-step', args.stop_step is not None), ('--keep-going', args.keep_going),
        ('--namespace', args.namespace is not None)) if value]
    if not stepwise and step_options:
        parser.error(f'{", ".join(step_options)} need(s) --step-period (step by step)')
    if stepwise and args.topics:
        parser.error('--only does not go with --step-period: a step by step replay sends '
                     "each episode's reset and commands")
    with recording.stop_on_signals():
        if not stepwise:
            n = play(args.bag, rate=None if args.fast else args.rate, topics=args.topics,
                     domain_id=args.domain_id, log=say,
                     wait_for_subscribers_s=PLAY_WAIT_S if args.wait is None else args.wait)
            print(f'published {n} messages')
            return 0
        report = play_steps(args.bag, episode=args.episode, start_step=args.start_step,
                            stop_step=args.stop_step, step_period_s=args.step_period,
                            keep_going=args.keep_going, step_timeout_s=args.step_timeout,
                            namespace=args.namespace, domain_id=args.domain_id, log=say,
                            wait_for_subscribers_s=10.0 if args.wait is None else args.wait)
    print(f'{report.requests} request(s) sent, {report.answered} answered, '
          f'{len(report.failures)} failed' + (f'; STOPPED: {report.stopped}'
                                              if report.stopped else ''))
    for failure in report.failures:
        print(f'  failed: {failure}')
    return 1 if report.failures or report.stopped else 0


if __name__ == '__main__':
    sys.exit(main())
