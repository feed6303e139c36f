"""Random vs oracle returns per challenge and setting (``growspace-eval``).

Both agents play the same seeded episodes; the table gives the mean 50-step return with its
standard error over the episodes. Usage::

    growspace-eval --episodes 100            # the README table (seconds on one core)
    growspace-eval --episodes 5 --csv out.csv
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
import sys
import time

import growspace_sim  # noqa: F401  (registers the ids)
from growspace_sim import arguments
from growspace_sim.agents.evaluation import evaluate as play, has_oracle, make_agent, mean_se
from growspace_sim.core import task as tasks
from growspace_sim.envs.registration import env_id, register_envs

COLUMNS = ('challenge', 'setting', 'episodes', 'random_mean', 'random_se', 'oracle_mean',
           'oracle_se', 'oracle_success')
NAN = float('nan')


@dataclass(frozen=True)
class Row:
    challenge: str
    setting: str
    episodes: int
    random_mean: float
    random_se: float
    oracle_mean: float  # NaN for a challenge without an oracle (Task.oracle is optional)
    oracle_se: float
    oracle_success: float  # fraction of oracle episodes whose last step reached the goal


def evaluate(challenge: str, setting: str, episodes: int, seed: int = 0) -> Row:
    """Play ``episodes`` seeded episodes with each agent on the discrete env."""
    names = ('random', 'oracle') if has_oracle(challenge) else ('random',)
    played = play(env_id(challenge, setting),
                  {name: lambda env, name=name: make_agent(name, env, seed) for name in names},
                  range(seed, seed + episodes))
    oracle = played.get('oracle')
    return Row(challenge, setting, episodes, *mean_se(played['random'].returns),
               *(mean_se(oracle.returns) if oracle else (NAN, NAN)),
               float(oracle.success.mean()) if oracle else NAN)


def markdown(rows: list[Row]) -> str:
    lines = ['| challenge | setting | random | oracle | oracle success |',
             '|---|---|---|---|---|']
    for r in rows:
        oracle = f'{r.oracle_mean:.2f} ± {r.oracle_se:.2f}' if r.oracle_mean == r.oracle_mean \
            else '- (no oracle)'
        success = '-' if r.oracle_success != r.oracle_success else f'{r.oracle_success:.0%}'
        lines.append(f'| {r.challenge} | {r.setting} | {r.random_mean:.2f} ± {r.random_se:.2f} '
                     f'| {oracle} | {success} |')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = arguments.Parser(prog='growspace-eval', description=__doc__.splitlines()[0])
    parser.add_argument('--episodes', type=arguments.integer(2), default=100,
                        help='episodes per agent and case (2 or more: a standard error)')
    parser.add_argument('--seed', type=arguments.SEED, default=0, help='first episode seed')
    known = arguments.checked(tasks.get)
    parser.add_argument('--challenges', type=arguments.comma_separated(known),
                        default=','.join(tasks.names()),
                        help='comma-separated; a name or module:attribute of your own Task')
    parser.add_argument('--settings', help="comma-separated; default: each challenge's own")
    parser.add_argument('--csv', type=arguments.new_file,
                        help='also write the rows to this CSV file')
    args = parser.parse_args(argv)
    cases = []
    for challenge in args.challenges:
        task = tasks.get(challenge)
        settings = args.settings.split(',') if args.settings else task.settings
        cases += [(challenge, setting) for setting in settings]
        unknown = sorted(set(settings) - set(task.settings))
        if unknown:
            parser.error(f'--settings: {challenge} has no setting {unknown}; it has '
                         f'{", ".join(task.settings)}')
    register_envs()  # the ids of a challenge loaded from a module of your own
    start = time.perf_counter()
    rows = []
    for challenge, setting in cases:
        rows.append(evaluate(challenge, setting, args.episodes, args.seed))
        print(f'{challenge}/{setting} done', file=sys.stderr)
    print(f'Mean 50-step return ± s.e. over {args.episodes} seeded episodes '
          f'(seeds {args.seed}..{args.seed + args.episodes - 1}), '
          f'{time.perf_counter() - start:.0f} s\n')
    print(markdown(rows))
    if args.csv:
        with open(args.csv, 'w', newline='') as f:
            writer = csv.writer(f)
            writer.writerow(COLUMNS)
            for r in rows:
                writer.writerow([getattr(r, c) for c in COLUMNS])
    return 0


if __name__ == '__main__':
    sys.exit(main())
