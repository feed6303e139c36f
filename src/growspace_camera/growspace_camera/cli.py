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
    growspace-camera resegment IN.mcap OUT.mcap [--params FILE.yaml] [--set NAME=VALUE ...]
        Measure every photo of a rig's recording again with other settings, into a new
        recording (docs/recording.md); the input is only read.
    growspace-camera export BAG DIR [--params ...] [--set ...] [--format jpg|png]
        Every photo of a rig's recording with what the camera saw drawn over it.

Settings (``--params``, ``--set``) are camera_node's pipeline parameters (docs/hardware.md);
they start from those a re-segmented recording holds, else from camera_node's defaults.

Exit status: 0 done, 1 a photo could not be measured (``measure``), 2 bad arguments or an
unreadable recording.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

import cv2
import yaml

from growspace_camera.capture import CaptureError, read_photo
from growspace_camera.measure import Target
from growspace_camera.photo_export import export_photos, FORMATS, SCALE_RANGE
from growspace_camera.pipeline import overlay, Pipeline
from growspace_camera.resegment import recorded_settings, resegment
from growspace_camera.settings import (
    CameraParams, load_layout, PIPELINE_FIELDS, pipeline_values, read_overrides, with_overrides)
from growspace_camera.sheet import describe, write_sheet
from growspace_camera.twin import PhotoTwin
from growspace_sim import arguments
from growspace_sim.core import task as tasks
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import initial_light
from growspace_sim.node.params import ParamError
from growspace_sim.recording import RecordingError
from growspace_sim.replay.bag import ReplayError
from growspace_sim.simulation import Simulation


def main(argv: list[str] | None = None) -> int:
    """Console script ``growspace-camera``."""
    parser = arguments.Parser(prog='growspace-camera', description=__doc__.split('\n')[0])
    sub = parser.add_subparsers(dest='command', required=True)
    markers = sub.add_parser('markers', help='write the printable marker sheet (SVG)')
    markers.add_argument('sheet', type=arguments.new_file,
                         help='the SVG file to write (e.g. sheet.svg)')
    twin = sub.add_parser('twin', help='photograph a simulated episode with the photo twin')
    twin.add_argument('out', type=arguments.folder, help='folder for the photos (created)')
    twin.add_argument('--steps', type=arguments.integer(0), default=50,
                      help='oracle steps after the first photo (default 50: 51 photos)')
    measure = sub.add_parser('measure', help='measure photos with the camera pipeline')
    measure.add_argument('photos', nargs='+', type=arguments.existing_file)
    measure.add_argument('--target-x', type=arguments.number(), help='point target x [m]')
    measure.add_argument('--target-z', type=arguments.number(), help='point target z [m]')
    measure.add_argument('--overlay', type=arguments.folder,
                         help='write the segmentation pictures to this folder')
    measure.add_argument('--lens', type=arguments.existing_file,
                         help="the camera's calibration YAML (ROS camera_calibration's; "
                              'default: no lens distortion)')
    for p in (markers, twin, measure):
        p.add_argument('--markers', type=arguments.existing_file,
                       help='marker layout YAML (default: installed)')
    reseg = sub.add_parser('resegment', help="measure a rig's recording again with other "
                                             'settings, into a new recording')
    reseg.add_argument('bag', type=arguments.existing_file,
                       help='the recording (gantry_node record_path, with a camera)')
    reseg.add_argument('out', type=arguments.new_file,
                       help='the new .mcap file (never an existing one)')
    export = sub.add_parser('export', help="a rig's recorded photos with what the camera saw")
    export.add_argument('bag', type=arguments.existing_file)
    export.add_argument('out', type=arguments.folder,
                        help='folder for the pictures (created; or an empty one)')
    export.add_argument('--format', default='jpg', choices=FORMATS)
    export.add_argument('--scale', type=arguments.number(*SCALE_RANGE), default=0.5,
                        help=f'picture size relative to the photo, {SCALE_RANGE[0]}..'
                             f'{SCALE_RANGE[1]} (default 0.5)')
    for p in (reseg, export):
        p.add_argument('--params', metavar='FILE.yaml', type=arguments.existing_file,
                       help="pipeline settings: name: value, or camera_node's ROS params file")
        p.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                       help=f'one pipeline setting (after --params), of: '
                            f'{", ".join(PIPELINE_FIELDS)}')
        p.add_argument('--namespace', type=arguments.namespace,
                       help='the chamber namespace (default: the only one)')
    for p in (twin, measure):
        p.add_argument('--challenge', type=arguments.checked(tasks.get), default='control',
                       help=f'one of {", ".join(tasks.names())}, or module:attribute of a Task '
                            'of your own (default control)')
        p.add_argument('--setting', default='easy', help='a setting of the challenge')
        p.add_argument('--seed', type=arguments.SEED, default=0)
    args = parser.parse_args(argv)
    if args.command in ('resegment', 'export'):
        return _recorded(args)
    cfg = None
    if args.command != 'markers':
        try:  # the setting's names depend on the challenge: checked together
            cfg = SimConfig(challenge=args.challenge, setting=args.setting)
        except ValueError as e:
            sub.choices[args.command].error(f'argument --setting: {e}')
    try:
        layout = load_layout(args.markers or '')
    except ParamError as e:
        if args.markers:
            sub.choices[args.command].error(f'argument --markers: {e}')
        print(f'growspace-camera: error: {e}', file=sys.stderr)  # the installed layout
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
    try:
        pipeline = Pipeline(CameraParams(lens=args.lens or '').pipeline(layout))
    except ParamError as e:
        print(f'growspace-camera: error: argument --lens: {e}', file=sys.stderr)
        return 2
    failed = 0
    for path in args.photos:
        try:
            photo, _ = read_photo(path)
        except CaptureError as e:
            print(f'NOT MEASURED: {e}')
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


def _recorded(args: argparse.Namespace) -> int:
    """``resegment`` and ``export``: a recording's photos measured with chosen settings."""
    def warn(line: str) -> None:
        print(f'warning: {line}', file=sys.stderr)

    try:
        params, base = recorded_settings(args.bag)
        if args.params:
            params = with_overrides(params, read_overrides(args.params), args.params)
        params = with_overrides(params, _pairs(args.set), '--set')
        changed = {k: v for k, v in pipeline_values(params).items()
                   if getattr(CameraParams(), k) != v}
        print(f'settings: {base}' + (f', with {changed}' if changed else ''))
        if args.command == 'resegment':
            report = resegment(args.bag, args.out, params, base=base, namespace=args.namespace,
                               warn=warn)
            print(f'wrote {args.out}: {report.photos} photo(s) measured again, {report.measured} '
                  f'read (recorded: {report.was_measured}), {report.changed} step(s) changed'
                  + (f', {report.lost} step(s) whose photo is unreadable now unmeasured'
                     if report.lost else ''))
        else:
            report = export_photos(args.bag, args.out, params, fmt=args.format,
                                   scale=args.scale, namespace=args.namespace, warn=warn)
            print(f'wrote {report.files} picture(s) to {args.out} ({report.measured} with a '
                  f'plant read)')
    except (ParamError, ReplayError, RecordingError) as e:
        print(f'growspace-camera: error: {e}', file=sys.stderr)
        return 2
    except OSError as e:
        print(f'growspace-camera: error: {e.strerror or e}'
              f'{f" ({e.filename})" if e.filename else ""}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    return 0


def _pairs(items: list[str]) -> dict[str, object]:
    """``--set NAME=VALUE`` arguments, each value read as YAML (0.1 a number, abc a string)."""
    values = {}
    for item in items:
        name, sep, text = item.partition('=')
        if not sep or not name.strip():
            raise ParamError(f'--set {item!r}: expected NAME=VALUE, e.g. --set min_greenness=0.1')
        try:
            values[name.strip()] = yaml.safe_load(text)
        except yaml.YAMLError:
            values[name.strip()] = text
    return values


if __name__ == '__main__':
    sys.exit(main())
