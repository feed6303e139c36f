"""``gantry_node`` entry point: the LED gantry on rclpy (``ros2 run growspace_gantry
gantry_node``).

Exit codes: 0 after SIGINT or SIGTERM (the lamp is switched off and the machine left idle
first); 2 for an invalid parameter or calibration (one line naming it, its value and what is
allowed). A controller that cannot be reached at start is retried with back-off, as after an
unplug: the node runs and says so on ``gantry/status``.
"""

from __future__ import annotations

from collections.abc import Sequence
import dataclasses
import logging
import os
import sys
import threading
from typing import Any

from growspace_gantry import calibration
from growspace_gantry.controller import GrblController, Log
from growspace_gantry.link import SerialLink
from growspace_gantry.node import GantryNode
from growspace_gantry.resume import GantryResume, load, ResumeError
from growspace_gantry.settings import GantryParams
from growspace_sim.core.config import SimConfig
from growspace_sim.node import params
from growspace_sim.node.main import console_main, make_recorder, run_node
from growspace_sim.node.params import NodeParams, ParamError
from growspace_sim.ros.share import share_file

NODE_NAME = 'growspace_gantry'

log = logging.getLogger('growspace_gantry.gantry_node')


def default_calibration() -> str:
    """The installed ``config/gantry.yaml`` (or the source tree's, when not installed)."""
    return str(share_file('growspace_gantry', 'config', 'gantry.yaml'))


def load_resume(path: str) -> GantryResume | None:
    """``resume_path``'s last episode (``resume.py``), None when empty or holding none.

    Raises:
        ParamError: it cannot be read or continued.
    """
    if not path:
        return None
    try:
        return load(path)
    except ResumeError as e:
        raise ParamError(str(e)) from None


def run(argv: Sequence[str], stop: threading.Event) -> int:
    """Run the node until SIGINT/SIGTERM or ``stop``; the lamp is off when it returns."""
    def start(transport: Any) -> GantryNode:
        # Read at start-up only (read-only parameters): a rig is reconfigured by restart.
        specs = params.specs_of(SimConfig, GantryParams, runtime=False)
        values, unknown = transport.declare_parameters(specs, params.check_type)
        # The simulator's params file works here too: its node-only settings mean nothing to
        # a gantry, which says so once; anything else is a typo until proven otherwise.
        sim_only = sorted(set(unknown) & {f.name for f in dataclasses.fields(NodeParams)})
        typos = sorted(set(unknown) - set(sim_only))
        if sim_only:
            transport.logger.info(f'gantry_node: sim_node parameter(s) {sim_only} do not '
                                  f'apply to a gantry; ignored.')
        if typos:
            transport.logger.warn('params:unknown', f'ignored unknown parameter(s) '
                                  f'{typos}: not parameters of gantry_node (a typo?)')
        cfg, settings = params.build(values, GantryParams)
        cal = calibration.load(settings.calibration or default_calibration())
        resume = load_resume(settings.resume_path)  # before a new split file opens there
        same = bool(settings.resume_path) and os.path.abspath(settings.resume_path) == \
            os.path.abspath(settings.record_path)
        recorder = make_recorder(settings.record_path, settings.record_max_bytes,
                                 settings.record_max_duration_s, append=same)
        logger = transport.logger
        controller = GrblController(lambda: SerialLink(settings.port, settings.baud), cal,
                                    Log(logger.warn, logger.info), 1.0 / settings.status_hz,
                                    photo_light=settings.photo_light)
        node = GantryNode(transport, controller, cfg, settings, recorder, resume=resume)
        logger.info(f'gantry_node {transport.resolve("~")}: {settings.mode} mode, '
                    f'{cfg.challenge} light, port {settings.port}'
                    + (f', recording to {settings.record_path}' if recorder else ''))
        return node
    return run_node('gantry_node', NODE_NAME, argv, stop, start,
                    bad_input=(ParamError, calibration.CalibrationError))


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``gantry_node``."""
    return console_main(run, argv, 'gantry_node stopped by a signal (lamp off, machine idle)',
                        log)


if __name__ == '__main__':
    sys.exit(main())
