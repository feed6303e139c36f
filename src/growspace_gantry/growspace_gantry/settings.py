"""The gantry node's own settings (beside every ``SimConfig`` field, which decides the light)."""

from __future__ import annotations

from dataclasses import dataclass
import math
import re

from growspace_sim.convert import MAX_SEED
from growspace_sim.node.params import MODES, ParamError


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
        if isinstance(self.baud, bool) or not isinstance(self.baud, int) or self.baud <= 0:
            raise ParamError(f'baud must be a positive integer, got {self.baud!r}.')
        for name, low, high in (('watchdog_s', 0.0, 1e6), ('lamp_power', 0.0, 1.0),
                                ('status_hz', 0.5, 50.0), ('move_timeout_s', 0.1, 1e6)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or not low <= value <= high:
                raise ParamError(f'{name} must be a number in [{low:g}, {high:g}], '
                                 f'got {value!r}.')
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) \
                or not -1 <= self.seed <= MAX_SEED:
            raise ParamError(f'seed must be -1 (random) or an int in [0, {MAX_SEED}], '
                             f'got {self.seed!r}.')
        if not isinstance(self.frame_id, str) or not re.fullmatch(r'[A-Za-z0-9_/]+',
                                                                  self.frame_id):
            raise ParamError(f'frame_id must be a frame name of letters, digits, _ and /, '
                             f'got {self.frame_id!r}.')
        for name in ('calibration', 'record_path'):
            if not isinstance(getattr(self, name), str):
                raise ParamError(f'{name} must be a string, got {getattr(self, name)!r}.')
