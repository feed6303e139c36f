"""``growspace-camera``: the camera's console tool.

    growspace-camera markers sheet.svg [--markers layout.yaml]
        Write the printable marker sheet (SVG in mm: print at 100 %) and say where each
        marker goes in the chamber frame.
    growspace-camera twin OUT_DIR [--challenge control --setting easy --seed 0 --steps 50]
        Photograph a simulated episode (oracle actions) with the photo twin, one JPEG a step:
        a folder camera_node can read (``source:=OUT_DIR``) or ``measure`` below.
    growspace-camera measure PHOTO... [--challenge ... --target-x X --target-z Z]
        Measure photos (a fixed light, for trying thresholds on real photos): one line per
        photo with the reward and how sure it is; ``--overlay DIR`` writes what was seen.

Exit status: 0 done, 1 a photo could not be measured (``measure``), 2 bad arguments.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

import cv2

from growspace_camera.measure import Target
from growspace_camera.pipeline import overlay, Pipeline
from growspace_camera.settings import CameraParams, load_layout
from growspace_camera.sheet import describe, write_sheet
from growspace_camera.twin import PhotoTwin
from growspace_sim.core import task as tasks
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import initial_light
from growspace_sim.node.params import ParamError
from growspace_sim.simulation import Simulation


def main(argv: list[str] | None = None) -> int:
    """Console script ``growspace-camera``."""
    parser = argparse.ArgumentParser(prog='growspace-camera', description=__doc__.split('\n')[0])
    sub = parser.add_subparsers(dest='command', required=True)
    markers = sub.add_parser('markers', help='write the printable marker sheet (SVG)')
    markers.add_argument('sheet', help='the SVG file to write (e.g. sheet.svg)')
    twin = sub.add_parser('twin', help='photograph a simulated episode with the photo twin')
    twin.add_argument('out', help='folder for the photos (created)')
    twin.add_argument('--steps', type=int, default=50)
    measure = sub.add_parser('measure', help='measure photos with the camera pipeline')
    measure.add_argument('photos', nargs='+')
    measure.add_argument('--target-x', type=float, help='point target x [m]')
    measure.add_argument('--target-z', type=float, help='point target z [m]')
    measure.add_argument('--overlay', help='write the segmentation pictures to this folder')
    for p in (markers, twin, measure):
        p.add_argument('--markers', default='', help='marker layout YAML (default: installed)')
    for p in (twin, measure):
        p.add_argument('--challenge', default='control',
                       help=f'one of {", ".join(tasks.names())}, or module:attribute of a Task '
                            'of your own (default control)')
        p.add_argument('--setting', default='easy', help='a setting of the challenge')
        p.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    try:
        layout = load_layout(args.markers)
        cfg = SimConfig(challenge=args.challenge, setting=args.setting) \
            if args.command != 'markers' else None
    except (ParamError, ValueError) as e:
        print(f'growspace-camera: {e}', file=sys.stderr)
        return 2
    if args.command == 'markers':
        for path in write_sheet(layout, args.sheet):
            print(f'wrote {path}')
        print(describe(layout))
        return 0
    if args.command == 'twin':
        return _twin(layout, cfg, args.seed, args.steps, Path(args.out))
    return _measure(layout, cfg, args)


def _twin(layout, cfg: SimConfig, seed: int, steps: int, out: Path) -> int:  # noqa: ANN001
    if cfg.task.oracle is None:
        print(f'growspace-camera: the {cfg.challenge} challenge has no oracle to steer the '
              f"twin's episode", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    sim = Simulation(cfg)
    sim.reset(seed=seed)
    oracle, twin = cfg.task.oracle(), PhotoTwin(layout)
    for step in range(steps + 1):
        if step:
            sim.apply_discrete(oracle.act(sim.chamber))
            sim.step()
        photo = twin.photo(sim.chamber, seed * 1000 + step)
        (out / f'step_{step:04d}.jpg').write_bytes(photo.jpeg)
    print(f'wrote {steps + 1} photos of {cfg.challenge} {cfg.setting} seed {seed} to {out}')
    return 0


def _measure(layout, cfg: SimConfig, args: argparse.Namespace) -> int:  # noqa: ANN001
    if cfg.task.digits is not None:
        print('growspace-camera: measure takes point-target challenges only (a shape target '
              'comes with the episode)', file=sys.stderr)
        return 2
    sim = Simulation(cfg)
    sim.reset(seed=args.seed)  # the episode's layout: target and light, as the task draws
    target = sim.chamber.target
    if args.target_x is not None and args.target_z is not None:
        target = complex(args.target_x, args.target_z)
    light = initial_light(cfg, sim.chamber.light.x, sim.chamber.light.z)
    pipeline = Pipeline(CameraParams().pipeline(layout))
    failed = 0
    for path in args.photos:
        photo = cv2.imread(path, cv2.IMREAD_COLOR)
        if photo is None:
            print(f'{path}: not a photo OpenCV can read')
            failed += 1
            continue
        m = pipeline.measure(photo, cfg, light, Target(point=target))
        c = m.confidence
        if m.ok:
            print(f'{path}: reward {m.reward:.4f}, {c.tips} tips, {c.plant_pixels} plant px, '
                  f'markers {list(c.markers_seen)}{" (fit held)" if c.fit_held else ""}, '
                  f'{m.timings_ms["total"]:.1f} ms')
        else:
            print(f'{path}: NOT MEASURED: {m.error}')
            failed += 1
        if args.overlay:
            Path(args.overlay).mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(Path(args.overlay) / (Path(path).stem + '_seen.jpg')),
                        overlay(photo, m))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
