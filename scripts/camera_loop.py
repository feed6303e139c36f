"""A learned policy closed loop through the camera on the twin rig (issue 32, item 4).

Used by ``scripts/learning_budget.py camera``. For each policy that ``learning_budget.py
export`` wrote (the best PPO run of a challenge: its weights and its env id), ``--episodes``
episodes on seeds ``--seed``.. are played twice, as ``scripts/bench_camera.py``'s closed loop
plays the oracle:

* ``sim``: the policy sees the simulator's own observation (what it was trained on);
* ``camera``: after the reset and after every step the twin (``PhotoTwin``, default jitter)
  photographs the chamber and a ``Pipeline`` with camera_node's defaults measures the photo;
  the policy sees the measurement's observation. A refused photo leaves it the last one it
  had (none yet: the light stays).

Returns are the simulator's rewards (the real plant's); ratio = camera / sim per challenge.
The policy acts greedily (deterministic), as in the evaluation table.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def load_policy(path: Path):
    """The SB3 PPO model of an exported ``policy-<challenge>.pt`` (weights only) and its info."""
    import torch  # noqa: PLC0415

    from growspace_sim.learn import train as training  # noqa: PLC0415

    saved = torch.load(path, map_location='cpu', weights_only=True)
    env = training.make_env(saved['env'], 1, 0)
    model = training.build_model('ppo', env, 0, 'cpu', {'n_steps': 64, 'batch_size': 64})
    model.policy.load_state_dict(saved['state_dict'])
    env.close()
    return model, saved


def play(model, env_id: str, seed: int, mode: str, twin, pipeline_params) -> dict:
    """One episode; the simulator's return and the photos the pipeline refused."""
    import gymnasium as gym  # noqa: PLC0415

    from growspace_camera.measure import Target  # noqa: PLC0415
    from growspace_camera.pipeline import Pipeline  # noqa: PLC0415
    from growspace_sim.core.light import BEAM_ACTIONS, SPOT_ACTIONS  # noqa: PLC0415

    env = gym.make(env_id)
    observation, _ = env.reset(seed=seed)
    sim = env.unwrapped.sim
    cfg = sim.cfg
    stay = (SPOT_ACTIONS if cfg.uses_spotlight else BEAM_ACTIONS).index('stay')
    pipe = Pipeline(pipeline_params)
    seen, total, refused = None, 0.0, 0
    flips, mismatch = [], []  # camera mode: what the camera's view changes, step by step
    for step in range(cfg.episode_length + 1):
        if mode == 'sim':
            seen = observation
        else:
            photo = twin.photo(sim.chamber, seed=seed * 100 + step)
            m = pipe.measure(photo.bgr, cfg, sim.chamber.light.copy(),
                             Target(sim.chamber.target, sim.chamber.target_mask),
                             sim.chamber.steps)
            if m.ok:
                seen = m.observation
            else:
                refused += 1
        if step == cfg.episode_length:
            break
        action = stay if seen is None else int(model.predict(seen, deterministic=True)[0])
        if mode == 'camera' and seen is not None:
            own = int(model.predict(observation, deterministic=True)[0])
            flips.append(action != own)
            mismatch.append([float(np.mean(seen[..., c] != observation[..., c]))
                             for c in range(3)])
        observation, reward, terminated, truncated, _ = env.step(action)
        total += reward
    env.close()
    out = {'return': total, 'refused': refused}
    if flips:
        out['action_flips'] = float(np.mean(flips))
        out['pixel_mismatch'] = np.mean(mismatch, axis=0).tolist()
    return out


def run_camera_loop(args: argparse.Namespace) -> int:
    import torch  # noqa: PLC0415

    from growspace_camera.markers import MarkerLayout  # noqa: PLC0415
    from growspace_camera.pipeline import Pipeline  # noqa: PLC0415
    from growspace_camera.twin import PhotoTwin  # noqa: PLC0415
    from growspace_sim.learn.evaluate_policies import EVAL_ENV  # noqa: PLC0415

    import cv2  # noqa: PLC0415

    torch.set_num_threads(1)
    cv2.setNumThreads(1)  # one core per process; several run side by side
    twin, params = PhotoTwin(MarkerLayout()), Pipeline().params  # camera_node's defaults
    seeds = range(args.seed, args.seed + args.episodes)
    results = {}
    for path in sorted(Path(args.policies).glob('policy-*.pt')):
        model, saved = load_policy(path)
        challenge = path.stem.split('-', 1)[1]
        env_id = EVAL_ENV.get(saved['env'], saved['env'])  # the curriculum: all ten digits
        sim = [play(model, env_id, s, 'sim', twin, params) for s in seeds]
        cam = [play(model, env_id, s, 'camera', twin, params) for s in seeds]
        sim_r = np.array([e['return'] for e in sim])
        cam_r = np.array([e['return'] for e in cam])
        results[challenge] = dict(
            env=env_id, run=saved['run'], steps=saved['steps'], episodes=len(seeds),
            sim_mean=float(sim_r.mean()), camera_mean=float(cam_r.mean()),
            sim_se=float(sim_r.std(ddof=1) / np.sqrt(len(seeds))),
            camera_se=float(cam_r.std(ddof=1) / np.sqrt(len(seeds))),
            ratio=float(cam_r.mean() / sim_r.mean()) if sim_r.mean() else float('nan'),
            refused=int(sum(e['refused'] for e in cam)),
            same_return_episodes=int(np.sum(np.isclose(sim_r, cam_r))),
            seeds=list(seeds), sim_returns=sim_r.tolist(), camera_returns=cam_r.tolist(),
            # the share of steps where the policy acts otherwise on the camera's view than on
            # the simulator's own observation of the same chamber, and the share of pixels
            # that differ per channel (target red, plant green, light blue)
            action_flips=[e['action_flips'] for e in cam],
            pixel_mismatch=np.mean([e['pixel_mismatch'] for e in cam], axis=0).tolist())
        r = results[challenge]
        print(f'{challenge:10s} {env_id} ({saved["steps"]:,} steps): sim '
              f'{r["sim_mean"]:.2f} ± {r["sim_se"]:.2f}, camera {r["camera_mean"]:.2f} ± '
              f'{r["camera_se"]:.2f}, ratio {r["ratio"]:.3f}, refused photos {r["refused"]}, '
              f'action flips {np.mean(r["action_flips"]):.3f}, pixels off (r, g, b) '
              f'{np.round(r["pixel_mismatch"], 4).tolist()}',
              flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1) + '\n')
    ratios = [r['ratio'] for r in results.values()]
    print(f'camera_loop: policies={len(results)} episodes={args.episodes} '
          f'camera_ratio_min={min(ratios) if ratios else float("nan"):.3f}')
    return 0
