"""The main job (``./run.sh demo``): a chamber run by an agent, recorded to ``bags/``.

Runs one episode per challenge with the oracle agent in-process and writes, per episode, an
animated GIF of the observations to ``bags/``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import gymnasium as gym
import imageio.v2 as imageio
import numpy as np

import growspace_sim  # noqa: F401  (registers the ids)
from growspace_sim.agents import OracleAgent
from growspace_sim.core.config import CHALLENGES, SETTINGS
from growspace_sim.registration import env_id

GIF_SIDE = 252  # px; observations are scaled up with nearest-neighbour so pixels stay crisp


def record_gif(challenge: str, setting: str, seed: int, out_dir: Path) -> tuple[Path, float]:
    """Play one oracle episode and save it as a GIF; returns the path and the return."""
    env = gym.make(env_id(challenge, setting))
    agent = OracleAgent()
    obs, _ = env.reset(seed=seed)
    frames, total, done = [obs], 0.0, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(agent.act(obs, env))
        frames.append(obs)
        total += float(reward)
        done = terminated or truncated
    path = _unique(out_dir / f'{challenge}-{setting}-seed{seed}.gif')
    big = [cv2.resize(f, (GIF_SIDE, GIF_SIDE), interpolation=cv2.INTER_NEAREST) for f in frames]
    imageio.mimsave(path, big, duration=0.1, loop=0)
    return path, total


def _unique(path: Path) -> Path:
    """Never overwrite: add a time stamp when the name is taken."""
    if not path.exists():
        return path
    return path.with_name(f'{path.stem}-{time.strftime("%Y%m%d-%H%M%S")}{path.suffix}')


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', default='bags', help='output directory (default: bags/)')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--setting', default='hard', choices=SETTINGS)
    args = parser.parse_args(argv)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    for challenge in CHALLENGES:
        path, total = record_gif(challenge, args.setting, args.seed, out_dir)
        print(f'{challenge:10s} {args.setting}: oracle return {total:6.2f} -> {path}')
    return 0


if __name__ == '__main__':
    np.seterr(all='raise')  # a silent NaN would be a bug worth stopping for
    sys.exit(main())
