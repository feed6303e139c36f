"""``growspace-rig``: run an experiment on a chamber, resume it after a crash, show where it is.

    growspace-rig run RUN_DIR --policy oracle --episodes 5 --seed 100
    growspace-rig resume RUN_DIR
    growspace-rig status RUN_DIR

Exit status: 0 the run is finished, 1 it stopped on an error (the message says what to do;
``resume`` goes on), 2 bad arguments or no run directory, 130 interrupted (resume goes on).
"""

from __future__ import annotations

import argparse
import datetime as dt
import sys

from growspace_sim import arguments
from growspace_sim.rig.rundir import (
    CHAMBERS, format_progress, POLICY_KINDS, RunDir, RunDirError, RunSettings)

# Settings fields -> their option, so a bad value is named as the user wrote it.
_OPTIONS = {'policy': '--policy', 'policy_path': '--policy-path', 'challenge': '--challenge',
            'setting': '--setting', 'episodes': '--episodes', 'seed': '--seed',
            'chamber': '--chamber', 'namespace': '--namespace',
            'step_period_s': '--step-period', 'step_timeout_s': '--step-timeout',
            'retry_period_s': '--retry-period', 'record_max_bytes': '--record-max-bytes',
            'record_max_duration_s': '--record-max-duration', 'lights_on': '--lights-on',
            'lights_off': '--lights-off', 'utc_offset_h': '--utc-offset'}


def build_parser() -> argparse.ArgumentParser:
    parser = arguments.Parser(prog='growspace-rig', description=__doc__.split('\n')[0])
    sub = parser.add_subparsers(dest='command', required=True)
    run = sub.add_parser('run', help='create RUN_DIR and run the experiment in it')
    run.add_argument('run_dir', metavar='RUN_DIR', help='a new directory for the run')
    defaults = RunSettings()
    run.add_argument('--policy', choices=POLICY_KINDS, default=defaults.policy,
                     help='oracle (acts on the simulated twin), random, replay (the actions of '
                          'a recording, --policy-path) or model (a growspace-train run '
                          'directory, --policy-path)')
    run.add_argument('--policy-path', default='', metavar='PATH')
    run.add_argument('--challenge', default=defaults.challenge)
    run.add_argument('--setting', default=defaults.setting)
    run.add_argument('--episodes', type=int, default=defaults.episodes, metavar='N')
    run.add_argument('--seed', type=int, default=defaults.seed,
                     help='episode i is reset with seed SEED + i')
    run.add_argument('--chamber', choices=CHAMBERS, default=defaults.chamber,
                     help='sim: start sim_node, recording into RUN_DIR/recording; attach: a '
                          'running lockstep chamber in --namespace (sim_node, or gantry_node '
                          'with camera_node)')
    run.add_argument('--namespace', default='', help='the chamber to attach to')
    run.add_argument('--step-period', type=float, default=defaults.step_period_s,
                     metavar='SECONDS', help='at least this long from one step to the next '
                     '(0: as soon as answered; e.g. 3600 on the rig)')
    run.add_argument('--step-timeout', type=float, default=defaults.step_timeout_s,
                     metavar='SECONDS', help='the longest a step may take to be answered')
    run.add_argument('--retry-period', type=float, default=defaults.retry_period_s,
                     metavar='SECONDS', help='attach: how often a refused step (gantry alarm) '
                     'is tried again')
    run.add_argument('--record-max-bytes', type=int, default=defaults.record_max_bytes,
                     metavar='BYTES', help='split the recording into files of this many '
                     'message bytes')
    run.add_argument('--record-max-duration', type=float,
                     default=defaults.record_max_duration_s, metavar='SECONDS',
                     help='... and of at most this much log time (0: no limit)')
    run.add_argument('--lights-on', default='', metavar='HH:MM',
                     help='a photoperiod the runner keeps (local standard time): no step begins '
                     'before lights-on or after lights-off (sim_node; gantry_node has its own '
                     'lights_on/lights_off parameters, leave these out there)')
    run.add_argument('--lights-off', default='', metavar='HH:MM')
    run.add_argument('--utc-offset', type=float, default=0.0, metavar='HOURS',
                     help='local standard time minus UTC, all year (no DST)')
    for name in ('resume', 'status'):
        sub_parser = sub.add_parser(name, help='go on with RUN_DIR after a crash or a stop'
                                    if name == 'resume' else 'where RUN_DIR is')
        sub_parser.add_argument('run_dir', metavar='RUN_DIR')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Console script ``growspace-rig``."""
    parser = build_parser()
    args = parser.parse_args(argv)

    def fail(code: int, text: str) -> int:
        print(f'growspace-rig: error: {text}', file=sys.stderr)
        return code

    try:
        if args.command == 'run':
            values = {field: getattr(args, option.lstrip('-').replace('-', '_'))
                      for field, option in _OPTIONS.items()}
            try:
                settings = RunSettings(**values)
            except RunDirError as e:
                return fail(2, f'argument {_OPTIONS.get(e.field, e.field)}: {e}')
            from growspace_sim.core.config import SimConfig

            try:
                SimConfig(challenge=settings.challenge, setting=settings.setting)
            except ValueError as e:
                return fail(2, f'argument --challenge/--setting: {e}')
            if settings.policy_path:  # read it now: a bad path creates no run directory
                from growspace_sim.replay import ReplayError
                from growspace_sim.rig.policies import make_policy

                try:
                    make_policy(settings.policy, settings.policy_path, settings.seed)
                except (ValueError, ReplayError, OSError) as e:
                    return fail(2, f'argument --policy-path: {settings.policy_path!r} cannot '
                                   f'be used as a {settings.policy} policy: {e}')
            rundir = RunDir.create(args.run_dir, settings)
        else:
            rundir = RunDir(args.run_dir)
        if args.command == 'status':
            from growspace_sim.core.config import SimConfig

            length = SimConfig(challenge=rundir.settings.challenge,
                               setting=rundir.settings.setting).episode_length
            print(format_progress(rundir.settings, rundir.state, length,
                                  dt.datetime.now(dt.UTC), None, None))
            if rundir.state.pending:
                print(f'a step was in progress: {rundir.state.pending}')
            return 0 if rundir.state.episodes_done >= rundir.settings.episodes else 1
    except RunDirError as e:
        return fail(2, str(e))
    return _run(rundir, fail)


def _run(rundir: RunDir, fail) -> int:
    from growspace_sim.recording import stop_on_signals
    from growspace_sim.rig.chambers import make_chamber
    from growspace_sim.rig.runner import Runner, RunnerError
    from growspace_sim.rig.schedule import hold_for

    def say(line: str) -> None:
        print(line, flush=True)

    say(f'run {rundir.path}: {rundir.settings.policy} on {rundir.settings.chamber}, '
        f'{rundir.settings.episodes} episode(s) of {rundir.settings.challenge}/'
        f'{rundir.settings.setting}; journal {rundir.journal_path}')
    chamber = make_chamber(rundir)
    try:
        with stop_on_signals():
            Runner(rundir, chamber, say,
                   not_before=hold_for(rundir.settings.photoperiod)).run()
    except KeyboardInterrupt:
        say(f'stopped; `growspace-rig resume {rundir.path}` goes on at the next step.')
        return 130
    except (RunnerError, RunDirError, ValueError, TimeoutError, RuntimeError) as e:
        return fail(1, f'{e}\n`growspace-rig resume {rundir.path}` goes on from here once the '
                       f'cause is fixed.')
    finally:
        chamber.close()
    say(f'finished: {rundir.state.episodes_done} episode(s), returns '
        f'{[round(e.episode_return, 4) for e in rundir.state.episodes]}; recording in '
        f'{rundir.recording_path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
