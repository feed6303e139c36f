"""Train PPO, A2C, DQN or Rainbow with a CNN encoder on a GrowSpace env (``growspace-train``).

Stable-Baselines3 on vectorised envs (``DummyVecEnv`` by default: on a few cores the env is
cheaper than the process hop of ``SubprocVecEnv``; ``--vec native`` steps every env in one
``GrowSpaceVectorEnv`` through ``learn.native_vec.NativeVecEnv``, the same episodes for less).
PPO defaults are the paper's final hyperparameters (appendix "Hyperparameter Search").
A run directory holds::

    run.json          arguments, hyperparameters, versions, wall time, steps/s
    episodes.csv      one row per finished training episode: timestep, wall_s, env, return, length
    progress.csv      Stable-Baselines3's logger (losses, fps, ...); TensorBoard too if installed
    checkpoints/      <algo>_<steps>_steps.zip every --checkpoint-every steps
    model.zip         the final policy

Usage::

    growspace-train --algo ppo --env GrowSpace/Control-Easy-v0 --steps 100000 --seed 0
    growspace-train --algo rainbow --env GrowSpace/Control-Hard-v0 --steps 50000 --hp n_steps=5
    growspace-train --algo ppo --env GrowSpace/Control-Easy-v0 --steps 2000 --bridge   # over ROS
"""

from __future__ import annotations

import argparse
import ast
import csv
import importlib.util
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import A2C, DQN, PPO
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecMonitor

import growspace_sim  # noqa: F401  (registers the ids, also in subprocess workers)
from growspace_sim import arguments
from growspace_sim.learn.device_buffer import DeviceRolloutBuffer
from growspace_sim.learn.native_vec import NativeVecEnv
from growspace_sim.learn.networks import GrowSpaceCNN
from growspace_sim.learn.rainbow import Rainbow

ALGOS: dict[str, type[BaseAlgorithm]] = {'ppo': PPO, 'a2c': A2C, 'dqn': DQN, 'rainbow': Rainbow}
VEC_KINDS = ('dummy', 'subproc', 'native')
BUFFER_KINDS = ('sb3', 'device')  # PPO / A2C rollout buffers: SB3's, or learn.device_buffer

# The paper's final PPO hyperparameters (appendix table). "Number of steps" is the rollout
# length per env and "mini batch" the minibatch size; the table's Adam epsilon (0.25) and
# momentum rows are left at torch's Adam defaults, since SB3's PPO does not expose them and
# an epsilon of 0.25 would mostly disable Adam's per-parameter scaling.
PAPER_PPO: dict[str, Any] = dict(learning_rate=2.5e-4, n_steps=2500, batch_size=32, n_epochs=4,
                                 gamma=0.99, gae_lambda=0.95, clip_range=0.1, ent_coef=0.01,
                                 max_grad_norm=0.5)
# A2C and DQN: Stable-Baselines3 / rl-zoo Atari settings, scaled to a short budget.
DEFAULTS: dict[str, dict[str, Any]] = {
    'ppo': PAPER_PPO,
    'a2c': dict(learning_rate=7e-4, n_steps=5, gamma=0.99, gae_lambda=1.0, ent_coef=0.01,
                vf_coef=0.25, max_grad_norm=0.5),
    'dqn': dict(learning_rate=1e-4, buffer_size=30_000, learning_starts=1_000, batch_size=32,
                gamma=0.99, train_freq=4, gradient_steps=1, target_update_interval=1_000,
                exploration_fraction=0.1, exploration_final_eps=0.01),
    'rainbow': dict(learning_rate=6.25e-5, buffer_size=30_000, learning_starts=1_000,
                    batch_size=32, gamma=0.99, train_freq=4, gradient_steps=1,
                    target_update_interval=1_000, n_steps=3),
}
DEFAULT_ENVS = {'ppo': 2, 'a2c': 2, 'dqn': 1, 'rainbow': 1}


class EpisodeLog(BaseCallback):
    """Append one CSV row per finished training episode (from the ``Monitor`` wrapper's info)."""

    FIELDS = ('timestep', 'wall_s', 'env', 'return', 'length')

    def __init__(self, path: Path, wall_offset: float = 0.0) -> None:
        """``wall_offset``: seconds of earlier legs of a resumed run; their rows are kept."""
        super().__init__()
        self.path = path
        self.wall_offset = wall_offset
        self._file = None
        self._writer = None
        self._start = 0.0

    def _on_training_start(self) -> None:
        append = self.wall_offset > 0 and self.path.exists()
        self._file = open(self.path, 'a' if append else 'w', newline='')
        self._writer = csv.writer(self._file)
        if not append:
            self._writer.writerow(self.FIELDS)
        self._start = time.perf_counter() - self.wall_offset

    def _on_step(self) -> bool:
        for index, info in enumerate(self.locals.get('infos', ())):
            episode = info.get('episode')
            if episode is not None:
                wall = time.perf_counter() - self._start
                self._writer.writerow([self.num_timesteps, f'{wall:.2f}', index,
                                       f'{episode["r"]:.6f}', episode['l']])
        return True

    def _on_rollout_end(self) -> None:
        self._file.flush()

    def _on_training_end(self) -> None:
        self._file.close()


class WallClockLimit(BaseCallback):
    """Stop training after ``seconds`` of wall time (a budget in time rather than in steps)."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = seconds
        self._start = 0.0

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()

    def _on_step(self) -> bool:
        return time.perf_counter() - self._start < self.seconds


def parse_hp(items: list[str]) -> dict[str, Any]:
    """``['n_steps=500', 'clip_range=0.2']`` -> ``{'n_steps': 500, 'clip_range': 0.2}``."""
    result = {}
    for item in items:
        key, sep, value = item.partition('=')
        if not sep:
            raise ValueError(f'--hp expects key=value, got {item!r}.')
        try:
            result[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            result[key] = value
    return result


def make_env(env_id: str, n_envs: int, seed: int, env_kwargs: dict | None = None,
             vec: str = 'dummy', bridge: bool = False) -> VecEnv:
    """``n_envs`` copies of ``env_id`` with ``Monitor`` (episode returns), seeds seed..seed+n-1.

    ``vec``: ``dummy`` (one process), ``subproc`` (a process per env) or ``native`` (one
    ``GrowSpaceVectorEnv`` for all, with ``VecMonitor``). With ``bridge``, each copy is the
    ROS Gymnasium bridge env driving its own sim node.

    Raises:
        ValueError: an unknown ``vec``, or ``native`` with ``bridge``.
    """
    if vec not in VEC_KINDS:
        raise ValueError(f'vec must be one of {VEC_KINDS}, got {vec!r}.')
    if vec == 'native':
        if bridge:
            raise ValueError("vec='native' steps the chambers in process; the bridge needs "
                             "vec='dummy' or 'subproc'.")
        env = NativeVecEnv(env_id, n_envs, **(env_kwargs or {}))
        env.seed(seed)  # chamber i starts from seed + i, as make_vec_env seeds env i
        return VecMonitor(env)
    if bridge:
        env_id = bridge_env_id(env_id)
    vec_cls = SubprocVecEnv if vec == 'subproc' else DummyVecEnv
    vec_kwargs = {'start_method': 'forkserver'} if vec == 'subproc' else None
    return make_vec_env(env_id, n_envs=n_envs, seed=seed, env_kwargs=env_kwargs or {},
                        vec_env_cls=vec_cls, vec_env_kwargs=vec_kwargs)


def bridge_env_id(env_id: str) -> str:
    """``GrowSpace/Control-Easy-v0`` -> ``GrowSpaceROS/Control-Easy-v0``; registers those ids.

    Each env copy then starts its own lockstep ``sim_node`` and talks to it over ROS 2 topics
    (``growspace_gym_bridge``, over rclpy).
    """
    import growspace_gym_bridge  # noqa: F401, PLC0415  (registers GrowSpaceROS/...)
    name = env_id.split('/', 1)[1]
    return env_id if env_id.startswith('GrowSpaceROS/') else f'GrowSpaceROS/{name}'


def build_model(algo: str, env: VecEnv, seed: int, device: str = 'auto',
                hp: dict[str, Any] | None = None, features_dim: int = 512,
                rollout_buffer: str = 'sb3') -> BaseAlgorithm:
    """The SB3 model with the GrowSpace CNN encoder and the algorithm's defaults + ``hp``.

    ``rollout_buffer='device'`` (PPO, A2C) cuts the minibatches on the training device
    (``learn.device_buffer``): the same minibatches, fewer copies.
    """
    if algo not in ALGOS:
        raise ValueError(f'algo must be one of {", ".join(ALGOS)}, got {algo!r}.')
    if rollout_buffer not in BUFFER_KINDS:
        raise ValueError(f'rollout_buffer must be one of {BUFFER_KINDS}, got {rollout_buffer!r}.')
    kwargs = {**DEFAULTS[algo], **(hp or {})}
    if rollout_buffer == 'device':
        if algo not in ('ppo', 'a2c'):
            raise ValueError(f"rollout_buffer='device' is for ppo and a2c, not {algo!r} "
                             '(DQN and Rainbow replay their own buffer).')
        kwargs['rollout_buffer_class'] = DeviceRolloutBuffer
    policy_kwargs = dict(features_extractor_class=GrowSpaceCNN,
                         features_extractor_kwargs=dict(features_dim=features_dim))
    policy_kwargs.update(kwargs.pop('policy_kwargs', {}))
    policy = 'RainbowPolicy' if algo == 'rainbow' else 'CnnPolicy'
    return ALGOS[algo](policy, env, seed=seed, device=device, policy_kwargs=policy_kwargs,
                       verbose=0, **kwargs)


def train(algo: str, env_id: str, steps: int, seed: int = 0, out: str | os.PathLike = 'runs',
          n_envs: int | None = None, device: str = 'auto', hp: dict[str, Any] | None = None,
          env_kwargs: dict | None = None, vec: str = 'dummy', checkpoint_every: int = 25_000,
          progress_bar: bool = True, threads: int = 1, log_interval: int | None = None,
          bridge: bool = False, max_seconds: float | None = None, rollout_buffer: str = 'sb3',
          resume: bool = False) -> Path:
    """Train and save; returns the run directory (see the module docstring for its files).

    ``resume``: if ``out`` holds a ``model.zip`` and a ``run.json`` of an earlier leg, continue
    from them up to ``steps`` in all (nothing to do when reached). The model (weights, Adam
    state, steps) and the curriculum's clock carry over; the random streams do not (SB3 saves
    none): the new leg seeds numpy, torch and the envs with ``seed`` + the steps reached, so a
    resumed run is repeatable but not the same as one uninterrupted run. ``episodes.csv`` is
    appended to, SB3's ``progress.csv`` of the earlier legs is kept as
    ``progress_until_<steps>.csv``.
    """
    torch.set_num_threads(threads)  # more threads than cores beside other work: ~100x slower
    n_envs = n_envs or DEFAULT_ENVS[algo]
    run_dir = Path(out)
    (run_dir / 'checkpoints').mkdir(parents=True, exist_ok=True)
    before = _earlier_leg(run_dir) if resume else None
    if before and before['steps'] >= steps:
        return run_dir
    env = make_env(env_id, n_envs, seed, env_kwargs, vec, bridge)
    if before:
        model = ALGOS[algo].load(run_dir / 'model.zip', env=env, device=device)
        model.set_random_seed(seed + model.num_timesteps)  # numpy, torch, action space, envs
        if before.get('curriculum_clock') is not None:
            _set_curriculum_clock(env, before['curriculum_clock'])
        if (run_dir / 'progress.csv').exists():
            (run_dir / 'progress.csv').rename(run_dir / f'progress_until_{before["steps"]}.csv')
    else:
        model = build_model(algo, env, seed, device, hp, rollout_buffer=rollout_buffer)
    legs = list(before['legs']) if before else []
    wall_before = sum(leg['wall_s'] for leg in legs)
    formats = ['csv'] + (['tensorboard'] if importlib.util.find_spec('tensorboard') else [])
    model.set_logger(configure(str(run_dir), formats))
    callbacks = CallbackList([
        EpisodeLog(run_dir / 'episodes.csv', wall_before),
        CheckpointCallback(max(checkpoint_every // n_envs, 1), str(run_dir / 'checkpoints'),
                           name_prefix=algo)]
        + ([WallClockLimit(max_seconds)] if max_seconds else []))
    if log_interval is None:
        log_interval = 1 if algo == 'ppo' else (100 if algo == 'a2c' else 10)
    first = int(model.num_timesteps)
    start = time.perf_counter()
    model.learn(total_timesteps=steps - first, callback=callbacks, log_interval=log_interval,
                progress_bar=progress_bar and _has_progress_bar(), reset_num_timesteps=not before)
    wall = time.perf_counter() - start
    model.save(run_dir / 'model.zip')
    clock = _curriculum_clock(env)
    env.close()
    legs.append(dict(steps_from=first, steps_to=int(model.num_timesteps), wall_s=round(wall, 1),
                     steps_per_s=round((model.num_timesteps - first) / wall, 1)))
    total_wall = wall_before + wall
    import stable_baselines3  # noqa: PLC0415
    info = dict(algo=algo, env=env_id, steps=int(model.num_timesteps), steps_asked=steps,
                seed=seed, n_envs=n_envs, vec=vec, device=str(model.device), threads=threads,
                env_kwargs=env_kwargs or {}, bridge=bridge, max_seconds=max_seconds,
                rollout_buffer=before.get('rollout_buffer', 'sb3') if before else rollout_buffer,
                hyperparameters={**DEFAULTS[algo], **(hp or {})},
                wall_s=round(total_wall, 1),
                steps_per_s=round(model.num_timesteps / total_wall, 1), legs=legs,
                curriculum_clock=clock,
                torch=torch.__version__, stable_baselines3=stable_baselines3.__version__)
    (run_dir / 'run.json').write_text(json.dumps(info, indent=2, default=str) + '\n')
    return run_dir


def _earlier_leg(run_dir: Path) -> dict | None:
    """run.json of an earlier leg with its model.zip, or None (a fresh run)."""
    if not ((run_dir / 'model.zip').exists() and (run_dir / 'run.json').exists()):
        return None
    info = json.loads((run_dir / 'run.json').read_text())
    info.setdefault('legs', [dict(steps_from=0, steps_to=info['steps'], wall_s=info['wall_s'],
                                  steps_per_s=info['steps_per_s'])])
    return info


def _curriculum_clock(env: VecEnv) -> list | None:
    """Episodes begun per chamber (the digit curriculum's clock), or None without one."""
    try:
        clock = env.get_attr('episodes')
    except AttributeError:
        return None
    if clock and isinstance(clock[0], list):  # the native vector env: one list for all
        return [int(n) for n in clock[0]]
    return [int(n) for n in clock]


def _set_curriculum_clock(env: VecEnv, clock: list[int]) -> None:
    if len(clock) != env.num_envs:
        raise ValueError(f'the run was trained on {len(clock)} envs, not {env.num_envs}: '
                         'resume it with the same --n-envs.')
    if isinstance(env.get_attr('episodes')[0], list):
        env.set_attr('episodes', list(clock))
    else:
        for i, episodes in enumerate(clock):
            env.set_attr('episodes', episodes, indices=[i])


def load_model(path: str | os.PathLike, device: str = 'cpu') -> BaseAlgorithm:
    """Load a run directory's ``model.zip`` or any checkpoint zip, finding its algo in run.json.

    The file is a pickle: Stable-Baselines3 restores parts of it with cloudpickle, so loading
    runs code it contains. Load only files you made, or that you would run as code.
    """
    path = Path(path)
    zip_path = path / 'model.zip' if path.is_dir() else path
    for parent in (zip_path.parent, zip_path.parent.parent):
        if (parent / 'run.json').exists():
            algo = json.loads((parent / 'run.json').read_text())['algo']
            break
    else:  # a checkpoint's file name starts with its algo
        algo = zip_path.name.split('_')[0]
    if algo not in ALGOS:
        raise ValueError(f'Cannot tell the algorithm of {zip_path}: no run.json beside it.')
    return ALGOS[algo].load(zip_path, device=device)


def _has_progress_bar() -> bool:
    return all(importlib.util.find_spec(m) for m in ('tqdm', 'rich'))


def main(argv: list[str] | None = None) -> int:
    parser = arguments.Parser(prog='growspace-train', description=__doc__.splitlines()[0],
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--algo', choices=sorted(ALGOS), default='ppo')
    parser.add_argument('--env', default='GrowSpace/Control-Easy-v0', help='a GrowSpace id')
    parser.add_argument('--steps', type=arguments.integer(1), default=100_000,
                        help='total env steps')
    parser.add_argument('--seed', type=arguments.SEED, default=0)
    parser.add_argument('--out', type=arguments.folder,
                        help='run directory (default runs/<algo>-<env>-s<seed>)')
    parser.add_argument('--n-envs', type=arguments.integer(1),
                        help='vectorised envs (default: 2 on-policy, 1 DQN)')
    parser.add_argument('--vec', choices=VEC_KINDS, default='dummy',
                        help='native: all envs in one GrowSpaceVectorEnv (not with --bridge)')
    parser.add_argument('--device', default='auto', help='cpu, cuda or auto')
    parser.add_argument('--threads', type=arguments.integer(1), default=1,
                        help='torch CPU threads')
    parser.add_argument('--hp', action='append', default=[], metavar='KEY=VALUE',
                        help='override a hyperparameter (repeatable), e.g. n_steps=500')
    parser.add_argument('--env-kwargs', type=arguments.json_object, default='{}',
                        help='JSON kwargs for gymnasium.make')
    parser.add_argument('--checkpoint-every', type=arguments.integer(1), default=25_000,
                        help='env steps')
    parser.add_argument('--log-interval', type=arguments.integer(1), help="SB3's log_interval")
    parser.add_argument('--max-minutes', type=arguments.number(0, low_open=True),
                        help='stop after this much wall time even if --steps is not reached')
    parser.add_argument('--no-progress-bar', action='store_true')
    parser.add_argument('--rollout-buffer', choices=BUFFER_KINDS, default='sb3',
                        help="ppo/a2c: 'device' cuts minibatches on the training device")
    parser.add_argument('--resume', action='store_true',
                        help='continue the run in --out from its model.zip up to --steps')
    parser.add_argument('--bridge', action='store_true',
                        help='train through the ROS Gymnasium bridge (growspace_gym_bridge)')
    args = parser.parse_args(argv)
    if args.env.startswith('GrowSpaceROS/'):
        args.bridge = True
    if args.vec == 'native' and args.bridge:
        parser.error('--vec native steps the chambers in process; with --bridge use dummy or '
                     'subproc')
    if args.rollout_buffer == 'device' and args.algo not in ('ppo', 'a2c'):
        parser.error(f'--rollout-buffer device is for ppo and a2c, not {args.algo}')
    if args.env not in gym.registry and not args.bridge:
        parser.error(f'unknown env id {args.env!r}')
    try:
        hp = parse_hp(args.hp)
    except ValueError as error:
        parser.error(str(error))
    name = args.env.split('/')[-1].rsplit('-', 1)[0].lower()
    out = args.out or os.path.join('runs', f'{args.algo}-{name}-s{args.seed}')
    run_dir = train(args.algo, args.env, args.steps, args.seed, out, args.n_envs, args.device, hp,
                    args.env_kwargs, args.vec, args.checkpoint_every,
                    not args.no_progress_bar, args.threads, args.log_interval, args.bridge,
                    args.max_minutes * 60 if args.max_minutes else None, args.rollout_buffer,
                    args.resume)
    info = json.loads((run_dir / 'run.json').read_text())
    returns = np.loadtxt(run_dir / 'episodes.csv', delimiter=',', skiprows=1, usecols=3, ndmin=1)
    tail = returns[-20:] if returns.size else np.array([np.nan])
    print(f'{run_dir}: {info["steps"]} steps in {info["wall_s"]} s ({info["steps_per_s"]} '
          f'steps/s), {returns.size} episodes, mean return of the last {tail.size}: '
          f'{tail.mean():.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
