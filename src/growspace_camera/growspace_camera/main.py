"""``camera_node`` entry point: the chamber's camera on rclpy (``ros2 run growspace_camera
camera_node``).

Exit codes: 0 after SIGINT or SIGTERM; 2 for an invalid parameter or marker layout (one line
naming it, its value and what is allowed). A camera that cannot be opened at start is retried
with back-off, as after an unplug: the node runs and says so on ``camera/status``.
"""

from __future__ import annotations

from collections.abc import Sequence
import logging
import sys
import threading
from typing import Any

from growspace_camera.capture import Camera, DeviceSettings, open_source
from growspace_camera.node import CameraNode
from growspace_camera.pipeline import Pipeline
from growspace_camera.settings import CameraParams, load_layout
from growspace_camera.twin.source import TwinSource
from growspace_sim.core.config import SimConfig
from growspace_sim.node import params
from growspace_sim.node.main import console_main, run_node
from growspace_sim.node.params import ParamError

NODE_NAME = 'growspace_camera'

log = logging.getLogger('growspace_camera.camera_node')


def build(transport: Any, values: dict[str, Any]) -> CameraNode:
    """The node from parameter values (what ``run`` declared; tests pass their own).

    Raises:
        ParamError: an invalid parameter or marker layout.
    """
    cfg, settings = params.build(values, CameraParams)
    layout = load_layout(settings.markers)
    device = DeviceSettings(settings.width, settings.height, settings.fps, settings.exposure,
                            settings.white_balance_k, settings.flush_frames)
    logger = transport.logger
    source = open_source(settings.source, device, settings.loop,
                         twin=lambda: TwinSource(layout, settings.twin_seed),
                         warn=lambda line: logger.warn(f'source:{line}', line))
    if settings.source != 'twin' and source.name.startswith('/dev/') and \
            (settings.exposure < 0 or settings.white_balance_k == 0):
        logger.warn('params:auto', f'camera_node: exposure and/or white balance left '
                    f'automatic on {source.name}: under a moving grow lamp every threshold '
                    f'drifts; set exposure and white_balance_k (docs/hardware.md)')
    camera = Camera(source, lambda line: logger.warn(f'camera:{line[:40]}', line),
                    logger.info, retry_max_s=settings.retry_max_s)
    node = CameraNode(transport, camera, Pipeline(settings.pipeline(layout)), cfg, settings)
    logger.info(f'camera_node {transport.resolve("~")}: {settings.mode} mode, source '
                f'{source.name}, markers {list(layout.ids)} ({layout.side * 1000:g} mm)')
    return node


def run(argv: Sequence[str], stop: threading.Event) -> int:
    """Run the node until SIGINT/SIGTERM or ``stop``."""
    def start(transport: Any) -> CameraNode:
        specs = params.specs_of(SimConfig, CameraParams, runtime=False)
        values, unknown = transport.declare_parameters(specs, params.check_type)
        if unknown:
            transport.logger.warn('params:unknown', f'ignored unknown parameter(s) '
                                  f'{unknown}: not parameters of camera_node (a typo?)')
        return build(transport, values)
    return run_node('camera_node', NODE_NAME, argv, stop, start, bad_input=(ParamError,))


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``camera_node``."""
    return console_main(run, argv, 'camera_node stopped by a signal', log)


if __name__ == '__main__':
    sys.exit(main())
