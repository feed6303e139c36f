"""``growspace-sweep``: run a spec file, or a grid given as flags."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


from growspace_sim import arguments
from growspace_sim.learn import evaluate_policies
from growspace_sim.sweep.report import summarise
from growspace_sim.sweep.spec import BASELINES, flags_spec, LEARNERS, load_spec, Spec, SpecError
from growspace_sim.sweep.trials import connect, disconnect, run_sweep


def main(argv: list[str] | None = None) -> int:
    import growspace_sim.sweep as package  # its docstring is the command's help

    parser = arguments.Parser(prog='growspace-sweep',
                              description=package.__doc__.splitlines()[0],
                              formatter_class=argparse.RawDescriptionHelpFormatter,
                              epilog=package.__doc__.split('Usage::')[1].split(
                                  '\n\nModules:')[0])
    parser.add_argument('spec', nargs='?', type=arguments.existing_file,
                        help='a YAML spec file (else the flags below)')
    parser.add_argument('--agents', help=f'comma-separated: {", ".join(BASELINES + LEARNERS)}')
    parser.add_argument('--envs', help='comma-separated GrowSpace ids')
    parser.add_argument('--seeds', default='1', help='a count (0..n-1) or a comma list')
    parser.add_argument('--steps', type=arguments.integer(1), help='training steps (learners)')
    parser.add_argument('--episodes', type=arguments.integer(2), default=50,
                        help='evaluation episodes per trial (2 or more: a standard error)')
    parser.add_argument('--eval-seed', type=arguments.SEED, default=10_000,
                        help='first evaluation seed')
    parser.add_argument('--name', help='experiment name (default: the spec file name)')
    parser.add_argument('--out', type=arguments.folder,
                        help='results folder (default runs/sweeps/<name>)')
    parser.add_argument('--storage', help="Ray Tune's storage: a folder every node of a "
                                          'cluster sees, or a URI (default: OUT)')
    parser.add_argument('--address', help='a Ray cluster to use (default: $RAY_ADDRESS, else '
                                          'a local instance on 127.0.0.1)')
    parser.add_argument('--workers', type=arguments.integer(1),
                        help='trials at once (default: all CPUs)')
    parser.add_argument('--cpus-per-trial', type=arguments.number(0, low_open=True), default=1.0)
    parser.add_argument('--gpus-per-trial', type=arguments.number(0), default=0.0)
    parser.add_argument('--retry-errored', action='store_true',
                        help='on resume, run failed trials again')
    parser.add_argument('--fresh-processes', action='store_true',
                        help='run every trial in a new worker process (slower)')
    parser.add_argument('--no-plots', action='store_true')
    parser.add_argument('--quiet', action='store_true', help='no Ray Tune status tables')
    args = parser.parse_args(argv)
    try:
        if args.spec:
            if args.agents or args.envs:
                parser.error('give a spec file or --agents/--envs, not both')
            spec = load_spec(args.spec)
            if args.name:
                spec = Spec(args.name, spec.episodes, spec.eval_seed, spec.trials)
        elif args.agents and args.envs:
            spec = flags_spec(args)
        else:
            parser.error('give a spec file, or --agents and --envs')
        out = Path(args.out or Path('runs') / 'sweeps' / spec.name)
        start = time.perf_counter()
        try:
            ray_context = connect(args.address, args.workers)
        except ConnectionError as error:
            # Ray's own error wraps the reason (e.g. a refused token) in a traceback's text.
            cause = str(error.__cause__ or '').strip().splitlines()
            print(f'growspace-sweep: error: {error}{f" ({cause[-1]})" if cause else ""}',
                  file=sys.stderr)
            return 1
        try:
            outcomes = run_sweep(spec, out, args.storage, args.workers, args.cpus_per_trial,
                                 args.gpus_per_trial, args.retry_errored,
                                 0 if args.quiet else 1, not args.fresh_processes)
        finally:
            if ray_context is not None:  # ours: stop it now, agents and all
                disconnect()
    except SpecError as error:
        parser.error(str(error))
    rows = summarise(outcomes, out, plots=not args.no_plots)
    failed = [o for o in outcomes if o.error]
    print(f'\n{spec.name}: {len(outcomes) - len(failed)} of {len(spec.trials)} trials finished, '
          f'{len(failed)} failed, {time.perf_counter() - start:.1f} s; results in {out}\n')
    print(evaluate_policies.markdown(rows))
    for o in failed:
        print(f'trial {o.trial.key} failed: {o.error}', file=sys.stderr)
    if len(outcomes) < len(spec.trials):
        print(f'Interrupted: {len(spec.trials) - len(outcomes)} trials did not finish; run the '
              'same command again to resume.', file=sys.stderr)
        return 130
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
