#!/usr/bin/env python3
"""The README's camera picture: docs/figures/camera_twin.jpg.

Left, a photo-twin photo of control (hard, seed 7, the oracle steering, step 30) with what the
pipeline saw (``pipeline.overlay``: the mask green, markers outlined, tips circled); right, the
simulator's own observation above the one the camera measured from that photo (84 px, shown
at 4x).

Usage (workspace sourced): python scripts/make_camera_figure.py [--out FILE.jpg]
"""

from __future__ import annotations

import argparse
import sys

import cv2
import numpy as np

from growspace_camera.markers import MarkerLayout
from growspace_camera.measure import Target
from growspace_camera.pipeline import overlay, Pipeline
from growspace_camera.twin import PhotoTwin
from growspace_sim.core.config import SimConfig
from growspace_sim.simulation import Simulation


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', default='docs/figures/camera_twin.jpg')
    args = parser.parse_args(argv)
    cfg = SimConfig(challenge='control', setting='hard')
    sim = Simulation(cfg)
    sim.reset(seed=7)
    oracle = cfg.task.oracle()
    for _ in range(30):
        sim.apply_discrete(oracle.act(sim.chamber))
        sim.step()
    c = sim.chamber
    photo = PhotoTwin(MarkerLayout()).photo(c, seed=30)
    m = Pipeline().measure(photo.bgr, cfg, c.light.copy(), Target(c.target), c.steps)
    assert m.ok, m.error
    seen = overlay(photo.bgr, m, 0.5)[:, 150:810]  # 540 x 660: the chamber and markers
    side = 270

    def big(rgb: np.ndarray) -> np.ndarray:
        return cv2.resize(rgb[..., ::-1], (side - 10, side - 10), interpolation=cv2.INTER_NEAREST)
    column = np.full((540, side, 3), 255, np.uint8)
    column[5:side - 5, 5:side - 5] = big(sim.observe())
    column[side + 5:2 * side - 5, 5:side - 5] = big(m.observation)
    picture = np.concatenate([seen, column], axis=1)
    cv2.imwrite(args.out, picture, (cv2.IMWRITE_JPEG_QUALITY, 85))
    print(f'wrote {args.out}: reward simulator {c.current_reward().reward:.3f}, camera '
          f'{m.reward:.3f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
