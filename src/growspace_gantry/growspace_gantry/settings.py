"""The gantry node's own settings (beside every ``SimConfig`` field, which decides the light)."""

from __future__ import annotations

from dataclasses import dataclass
import re

from growspace_sim.ros.convert import MAX_SEED
from growspace_sim.core.config import Bounds
from growspace_sim.node.params import check_bounds, MODES, ParamError

# The ranges of GantryParams' number fields: what validation checks and ROS parameters show.
GANTRY_BOUNDS = {
    'baud': Bounds(1, 4_000_000, integer=True), 'watchdog_s': Bounds(0.0, 1e6),
    'lamp_power': Bounds(0.0, 1.0), 'status_hz': Bounds(0.5, 50.0),
    'move_timeout_s': Bounds(0.1, 1e6), 'seed': Bounds(0, MAX_SEED, integer=True, sentinel=-1),
}


@dataclass(frozen=True)
class GantryParams:
    """Settings of gantry_node, validated on construction (ROS parameters of the same names)."""

    port: str = '/dev/ttyUSB0'  # serial device of the GRBL 1.1 controller
    baud: int = 115200  # serial baud rate (GRBL 1.1 default)
    calibration: str = ''  # calibration YAML; empty = the installed config/gantry.yaml
    mode: str = 'lockstep'  # lockstep: answer each step_id when the move is done; realtime
    watchdog_s: float = 10.0  # s without a command (after the last answer) -> lamp off, hold
    lamp_power: float = 1.0  # lamp power while lit, fraction of full power (S = $30) [1]
    status_hz: float = 10.0  # Hz; status reports asked of GRBL (and light/state in realtime)
    move_timeout_s: float = 120.0  # s; a lockstep move not done by then is answered as failed
    seed: int = -1  # seed of the first episode's light layout; -1 = draw one
    frame_id: str = 'chamber'  # frame of light state and step results
    record_path: str = ''  # MCAP file to record the hardware run to; empty = no recording

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ParamError(f'mode must be one of {MODES}, got {self.mode!r}.')
        if not isinstance(self.port, str) or not self.port:
            raise ParamError(f'port must be a serial device path, got {self.port!r}.')
        check_bounds(self, GANTRY_BOUNDS)
        if not isinstance(self.frame_id, str) or not re.fullmatch(r'[A-Za-z0-9_/]+',
                                                                  self.frame_id):
            raise ParamError(f'frame_id must be a frame name of letters, digits, _ and /, '
                             f'got {self.frame_id!r}.')
        for name in ('calibration', 'record_path'):
            if not isinstance(getattr(self, name), str):
                raise ParamError(f'{name} must be a string, got {getattr(self, name)!r}.')
