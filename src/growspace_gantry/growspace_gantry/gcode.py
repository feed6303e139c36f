"""``growspace-gantry-gcode BAG``: the dry run of a hardware replay, nothing sent anywhere.

For every step of a recording it prints the lines ``gantry_node`` would write to GRBL to put
the lamp where the simulator's light was (the recorded ``light/state``: the applied light,
after the simulator's clamping), through the same calibration and the same travel checks. A
step whose light the rig cannot reach is printed as a comment saying why: the node would
refuse it too.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
import sys

from growspace_gantry import calibration, grbl
from growspace_gantry.main import default_calibration
from growspace_sim import arguments
from growspace_sim.core.light import Light
from growspace_sim.replay.bag import Bag, ReplayError
from growspace_sim.replay.episodes import read_episodes


def gcode_lines(bag_path: str, cal: calibration.Calibration, episode: int | None = None,
                lamp_power: float = 1.0) -> Iterator[str]:
    """The dry run, line by line (comments start with ``;``).

    Args:
        bag_path: The recording.
        cal: The rig's calibration.
        episode: 0-based (negative from the end); None = every episode.
        lamp_power: The fraction of the calibration's full power (``lamp_max_s``), 0..1.

    Raises:
        ReplayError: the bag cannot be read or has no such episode.
        ValueError: ``lamp_power`` outside 0..1 (more would exceed the rig's ``$30``).
    """
    if not 0.0 <= lamp_power <= 1.0:
        raise ValueError(f'lamp_power = {lamp_power!r} is not allowed; expected a fraction of '
                         f'full power in [0, 1]')
    with Bag(bag_path) as bag:
        episodes = read_episodes(bag)
    if episode is not None:
        if not -len(episodes) <= episode < len(episodes):
            raise ReplayError(f'--episode {episode}: the recording has {len(episodes)} '
                              f'episode(s)')
        episodes = [episodes[episode]]
    lamp = grbl.lamp_line(lamp_power * cal.lamp_max_s)
    for ep in episodes:
        yield f'; episode {ep.index} (reset_id {ep.reset_id}, seed {ep.seed})'
        for problem in ep.damaged:  # a dry run shows what a replay of this bag would miss
            yield f'; incomplete: {problem}'
        for record in ep.steps:
            out = record.outputs.get('light/state')
            if out is None:
                continue
            msg = out.decode()
            light = Light(msg.mode == 1, msg.x, msg.z, msg.width, msg.radius)
            where = f'step {record.result.step} (step_id {record.result.step_id})'
            size = f'radius {light.radius:.4f}' if light.spot else f'width {light.width:.4f}'
            try:
                target = cal.to_machine(light)
            except calibration.TargetError as e:
                yield f'; {where}: NOT SENT: {e}'
                continue
            yield f'; {where}: x {light.x:.4f} m, {size} m'
            yield grbl.jog_line(target, cal.feed_mm_min)
            if lamp:
                yield lamp  # sent once the jog is done (GRBL refuses G-code while jogging)
                lamp = ''
    yield grbl.lamp_line(0.0)


def main(argv: list[str] | None = None) -> int:
    """Console script; exit 0, or 2 with one line on an unreadable bag or calibration."""
    parser = arguments.Parser(prog='growspace-gantry-gcode', description=__doc__.split('\n')[0])
    parser.add_argument('bag', type=arguments.existing_file)
    parser.add_argument('--calibration', type=arguments.existing_file,
                        help='default: the installed config/gantry.yaml')
    parser.add_argument('--episode', type=int, help='0-based, -1 = last; default: all')
    parser.add_argument('--lamp-power', type=arguments.number(0, 1), default=1.0,
                        help="fraction of the calibration's full power (lamp_max_s), 0..1")
    args = parser.parse_args(argv)
    try:
        cal = calibration.load(args.calibration or default_calibration())
        for line in gcode_lines(args.bag, cal, args.episode, args.lamp_power):
            print(line)
    except (ReplayError, calibration.CalibrationError, ValueError) as e:
        print(f'growspace-gantry-gcode: error: {e}', file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader stopped early (`| head`): not an error of ours
        # Python would complain again flushing stdout at exit; hand it a sink instead.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


if __name__ == '__main__':
    sys.exit(main())
