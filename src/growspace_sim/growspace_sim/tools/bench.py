"""Environment speed benchmark (``growspace-bench``), with a fixed method.

Per challenge (easy setting, discrete actions): uniform random actions from a seeded action
space (drawn before the clock starts), 50-step episodes, observations rendered every step,
through ``gymnasium.make`` (so the default wrappers are included) and the one episode loop
(``agents.evaluation.play_episodes``), and through ``gymnasium.make_vec(...,
vectorization_mode='vector_entry_point')`` with N = 1, 16, 64, 256 chambers (whole episodes:
``ceil(episodes / N)`` rounds of 51 vector steps, the 51st being the autoreset; each counts N
env steps). After one warm-up episode, it times ``--episodes`` episodes ``--repeats`` times and
reports the best repeat (the least disturbed by other processes), plus the core alone (no
rendering, no Gymnasium) on the same seeds so the ratio shows the overhead. The process is
pinned to one CPU. Rates are per second of the process's CPU time, which a shared virtual
machine's stolen time does not inflate; the wall-clock rate of the same repeat is shown beside
it. Also reported: mean reset time (resets alone, on the same seeds), mean segments per plant at
step 50 and the peak resident memory. A second table shows how resources grow with the episode
length and the light density: each row runs in a fresh process (its own peak memory), resets the
control env three times (best reset time) and plays one random episode.

    growspace-bench                 # all challenges
    growspace-bench --num-envs 64   # vector env with 64 chambers only
    growspace-bench --profile       # and where the time goes in control (cProfile top 15)
"""

from __future__ import annotations

import argparse
import concurrent.futures
import cProfile
import io
import multiprocessing
import os
import pstats
import resource
import sys
import time

import gymnasium as gym
import numpy as np

import growspace_sim  # noqa: F401  (registers the ids)
from growspace_sim import arguments
from growspace_sim.agents.evaluation import play_episodes
from growspace_sim.core import light as lights
from growspace_sim.core import task as tasks
from growspace_sim.core.chamber import Chamber
from growspace_sim.envs.registration import env_id
from growspace_sim.simulation import Simulation

TARGETS = {'control': 40_000}  # env steps/s on one core (issue 17; issue 9 asked 10,000)
VECTOR_TARGETS = {('control', 64): 100_000}  # vector env steps/s on one core (issue 17)
RESOURCE_ROWS = ({}, {'episode_length': 20_000}, {'light_density': 12_800})
RESOURCE_TARGETS = {'episode_length': (50.0, 200.0)}  # reset ms, peak MiB; from issue 10


class ScriptedAgent:
    """Actions drawn before the clock starts, so the timing holds no sampling."""

    def __init__(self, actions: list) -> None:
        self._actions = iter(actions)

    def act(self, observation: np.ndarray, env: gym.Env) -> int:
        return next(self._actions)


def run_env(name: str, episodes: int, seed: int) -> tuple[float, float, float, float]:
    """(CPU steps/s, wall steps/s, mean reset seconds, mean segments per plant at step 50)."""
    env = gym.make(name)
    env.action_space.seed(seed)
    agent = ScriptedAgent([env.action_space.sample() for _ in range(50 * episodes)])
    seeds = range(seed, seed + episodes)
    start, cpu_start = time.perf_counter(), time.process_time()
    played = play_episodes(env, agent, seeds)
    cpu, wall = time.process_time() - cpu_start, time.perf_counter() - start
    cpu_start = time.process_time()
    for episode_seed in seeds:  # resets alone, on the same seeds
        env.reset(seed=episode_seed)
    reset_time = (time.process_time() - cpu_start) / episodes
    env.close()
    segments = np.mean([np.mean(info['branch_counts']) for info in played.infos])
    return played.steps / cpu, played.steps / wall, reset_time, float(segments)


def run_vector(name: str, num_envs: int, episodes: int, seed: int) -> tuple[float, float]:
    """(CPU env steps/s, wall env steps/s) of the native vector env with ``num_envs`` chambers."""
    envs = gym.make_vec(name, num_envs=num_envs, vectorization_mode='vector_entry_point')
    envs.action_space.seed(seed)
    calls = -(-episodes // num_envs) * 51 - 1  # whole episodes, with the autoreset steps between
    actions = [envs.action_space.sample() for _ in range(calls)]
    envs.reset(seed=seed)
    start, cpu_start = time.perf_counter(), time.process_time()
    for action in actions:
        envs.step(action)
    cpu, wall = time.process_time() - cpu_start, time.perf_counter() - start
    envs.close()
    return calls * num_envs / cpu, calls * num_envs / wall


def run_core(challenge: str, episodes: int, seed: int) -> float:
    """Steps/s of the growth core alone (no rendering, no Gymnasium) on the same kind of run."""
    sim = Simulation(growspace_sim.core.SimConfig(challenge=challenge))
    chamber: Chamber = sim.chamber
    n_actions = len(lights.SPOT_ACTIONS if chamber.cfg.uses_spotlight else lights.BEAM_ACTIONS)
    actions = np.random.default_rng(seed).integers(n_actions, size=50 * episodes).tolist()
    steps = 0
    start = time.process_time()
    for episode in range(episodes):
        sim.reset(seed=seed + episode)
        for _ in range(50):
            lights.apply_discrete(chamber.light, actions[steps], chamber.cfg)
            chamber.step()
            steps += 1
    return steps / (time.process_time() - start)


def run_resources(overrides: dict[str, int], seed: int) -> tuple[float, float, float]:
    """(best reset ms, seconds of one random episode, peak RSS MiB) of the control env with
    these SimConfig overrides; call it in a fresh process for a meaningful peak."""
    env = gym.make(env_id('control', 'easy'), **overrides)
    reset_s = []
    for episode in range(3):
        t = time.perf_counter()
        env.reset(seed=seed + episode)
        reset_s.append(time.perf_counter() - t)
    env.action_space.seed(seed)
    start, truncated = time.perf_counter(), False
    while not truncated:
        truncated = env.step(env.action_space.sample())[3]
    episode_s = time.perf_counter() - start
    env.close()
    return min(reset_s) * 1e3, episode_s, peak_rss_mib()


def peak_rss_mib() -> float:
    """This process's peak resident memory in MiB.

    Linux keeps ``ru_maxrss`` across exec, so a freshly spawned child would report at least its
    parent's size; the kernel's per-image high-water mark (VmHWM) does not carry over.
    """
    try:
        with open('/proc/self/status') as status:
            for line in status:
                if line.startswith('VmHWM:'):
                    return int(line.split()[1]) / 1024  # kB
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB on Linux


def best_of(repeats: int, fn, *args):
    results = [fn(*args) for _ in range(repeats)]
    return max(results, key=lambda r: r[0] if isinstance(r, tuple) else r)


def main(argv: list[str] | None = None) -> int:
    parser = arguments.Parser(prog='growspace-bench', description=__doc__.splitlines()[0])
    parser.add_argument('--episodes', type=arguments.integer(1), default=200,
                        help='timed episodes per repeat')
    parser.add_argument('--repeats', type=arguments.integer(1), default=3)
    parser.add_argument('--seed', type=arguments.SEED, default=0)
    parser.add_argument('--challenges', type=arguments.comma_separated(_easy_challenge),
                        default=','.join(tasks.names()),
                        help=f'comma-separated, of {", ".join(tasks.names())}')
    parser.add_argument('--num-envs', type=arguments.comma_separated(arguments.integer(1),
                                                                     empty=True),
                        default='1,16,64,256',
                        help='vector env sizes, comma-separated ("" for none)')
    parser.add_argument('--no-resources', action='store_true',
                        help='skip the table of resources against episode length and density')
    parser.add_argument('--profile', action='store_true', help='profile the control env')
    args = parser.parse_args(argv)
    pinned = hasattr(os, 'sched_setaffinity')
    if pinned:
        cpus = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {min(cpus)})
    try:
        _report(args)
    finally:
        if pinned:
            os.sched_setaffinity(0, cpus)
    return 0


def _easy_challenge(name: str) -> str:
    """A challenge the benchmark can run (it times the easy setting)."""
    task = tasks.get(name)
    if 'easy' not in task.settings:
        raise ValueError(f'challenge {name!r} has no easy setting (it has '
                         f'{", ".join(task.settings)}); the benchmark times the easy one')
    return name


def _report(args: argparse.Namespace) -> None:
    print(f'GrowSpace env benchmark: {args.episodes} x 50-step episodes, best of {args.repeats}, '
          f'1 CPU, steps per CPU second, numpy {np.__version__}, '
          f'Python {sys.version.split()[0]}\n')
    print('| challenge | env steps/s | (wall) | core steps/s | env/core | reset ms '
          '| segments at step 50 | target |')
    print('|---|---|---|---|---|---|---|---|')
    for challenge in args.challenges:
        name = env_id(challenge, 'easy')
        run_env(name, 1, args.seed)  # warm-up: imports, caches, first allocations
        rate, wall, reset_s, segments = best_of(args.repeats, run_env, name, args.episodes,
                                                args.seed)
        core = best_of(args.repeats, run_core, challenge, args.episodes, args.seed)
        target = TARGETS.get(challenge)
        verdict = '' if target is None else \
            f'>= {target:,}: {"met" if rate >= target else "NOT met"}'
        print(f'| {challenge} | {rate:,.0f} | {wall:,.0f} | {core:,.0f} | {rate / core:.2f} | '
              f'{reset_s * 1e3:.2f} | {segments:.1f} | {verdict} |')
    sizes = args.num_envs
    if sizes:
        _report_vector(args, sizes)
    print(f'\npeak RSS {peak_rss_mib():.0f} MiB\n')
    if not args.no_resources:
        _report_resources(args)
    if args.profile:
        profiler = cProfile.Profile()
        profiler.runcall(run_env, env_id('control', 'easy'), 100, args.seed)
        out = io.StringIO()
        pstats.Stats(profiler, stream=out).sort_stats('tottime').print_stats(15)
        print(out.getvalue())


def _report_vector(args: argparse.Namespace, sizes: list[int]) -> None:
    print('\n| challenge | ' + ' | '.join(f'vector N={n}' for n in sizes) + ' | target |')
    print('|---|' + '---|' * len(sizes) + '---|')
    for challenge in args.challenges:
        name = env_id(challenge, 'easy')
        run_vector(name, sizes[0], 1, args.seed)  # warm-up
        rates = {n: best_of(args.repeats, run_vector, name, n, args.episodes, args.seed)[0]
                 for n in sizes}
        verdicts = [f'N={n} >= {VECTOR_TARGETS[challenge, n]:,}: '
                    f'{"met" if rates[n] >= VECTOR_TARGETS[challenge, n] else "NOT met"}'
                    for n in sizes if (challenge, n) in VECTOR_TARGETS]
        print(f'| {challenge} | ' + ' | '.join(f'{rates[n]:,.0f}' for n in sizes)
              + f' | {"; ".join(verdicts)} |')


def _report_resources(args: argparse.Namespace) -> None:
    print('| control env, changed from the defaults | reset ms | one episode s | peak RSS MiB '
          '| target |')
    print('|---|---|---|---|---|')
    spawn = multiprocessing.get_context('spawn')  # a fresh interpreter: its own peak RSS
    for overrides in RESOURCE_ROWS:
        with concurrent.futures.ProcessPoolExecutor(1, mp_context=spawn) as pool:
            reset_ms, episode_s, peak = pool.submit(run_resources, overrides, args.seed).result()
        label = ', '.join(f'{k} {v:,}' for k, v in overrides.items()) or 'none (defaults)'
        target = next((RESOURCE_TARGETS[k] for k in overrides if k in RESOURCE_TARGETS), None)
        verdict = '' if target is None else (
            f'< {target[0]:.0f} ms, < {target[1]:.0f} MiB: '
            f'{"met" if reset_ms < target[0] and peak < target[1] else "NOT met"}')
        print(f'| {label} | {reset_ms:.2f} | {episode_s:.2f} | {peak:.0f} | {verdict} |')


if __name__ == '__main__':
    sys.exit(main())
