"""The gantry node's own settings (beside every ``SimConfig`` field, which decides the light).

Each is declared once (``growspace_sim.core.schema.param``): its ROS parameter descriptor,
validation and the docs' table come from the declaration. ``python -m
growspace_gantry.settings`` prints docs/hardware.md's table of them.
"""

from __future__ import annotations

from dataclasses import dataclass

from growspace_sim.core import schema
from growspace_sim.core.photoperiod import Photoperiod
from growspace_sim.core.schema import Bounds, param
from growspace_sim.node.params import check, frame_param, mode_param, ParamError, seed_param

CLOCK = r'(|([01][0-9]|2[0-3]):[0-5][0-9])'  # HH:MM or empty


@dataclass(frozen=True)
class GantryParams:
    """Settings of gantry_node, validated on construction (ROS parameters of the same names)."""

    port: str = param('/dev/ttyUSB0', 'serial device of the GRBL 1.1 controller',
                      pattern=r'.+', pattern_doc='a serial device path')
    baud: int = param(115200, 'serial baud rate (GRBL 1.1 default)', unit='Bd',
                      bounds=Bounds(1, 4_000_000, integer=True))
    calibration: str = param('', 'calibration YAML; empty = the installed config/gantry.yaml')
    mode: str = mode_param('lockstep: answer each step_id when the move is done; realtime')
    watchdog_s: float = param(10.0, 'without a command (after the last answer) -> lamp off, '
                              'hold', unit='s', bounds=Bounds(0.0, 1e6))
    lamp_power: float = param(1.0, 'lamp power while lit (S = $30 at 1)',
                              unit='fraction of full power', bounds=Bounds(0.0, 1.0))
    status_hz: float = param(10.0, 'status reports asked of GRBL (and light/state in realtime)',
                             unit='Hz', bounds=Bounds(0.5, 50.0))
    move_timeout_s: float = param(120.0, 'a lockstep move not done by then is answered as '
                                  'failed', unit='s', bounds=Bounds(0.1, 1e6))
    seed: int = seed_param("seed of the first episode's light layout")
    frame_id: str = frame_param('chamber', 'frame of light state and step results')
    record_path: str = param('', 'MCAP file to record the hardware run to (with a limit below, '
                             'a split directory); empty = no recording')
    record_max_bytes: int = param(0, 'split the recording into files of about this many message '
                                  'bytes (as sim_node; rosbag2 --max-bag-size); 0 = one file',
                                  unit='B', bounds=Bounds(0, 10**15, integer=True))
    record_max_duration_s: float = param(0.0, 'split the recording into files of at most this '
                                         'much wall time each (rosbag2 --max-bag-duration); '
                                         '0 = no duration limit', unit='s', bounds=Bounds(0.0))
    resume_path: str = param('', "go on with the last episode of this gantry_node's recording "
                             '(a split directory): its reset_id, step count and last step_id '
                             'kept, the first relative action placed absolutely from the '
                             'recorded light; the same directory as record_path continues it '
                             'with a new file; empty = a new episode at start-up')
    camera: str = param('', "camera_node's capture service, called after each reached move "
                        '(lockstep): its measurement answers the step; empty = no camera: '
                        'light/state and step_result only, reward 0',
                        pattern=r'(|[~/A-Za-z_][A-Za-z0-9_/~{}]*)',
                        pattern_doc='a service name such as camera/capture, or empty')
    capture_timeout_s: float = param(10.0, 'longest wait for the capture service and its answer '
                                     '(after photo_settle_s); then the step fails', unit='s',
                                     bounds=Bounds(0.1, 3600.0))
    photo_light: bool = param(False, "a white photo light on GRBL's flood coolant output: "
                              'M8 for each photo, M9 after it and on every fault')
    photo_settle_s: float = param(0.5, 'wait after the photo light is on before the photo',
                                  unit='s', bounds=Bounds(0.0, 60.0))
    growth_s: float = param(0.0, "a lockstep step's growth period (the simulator's one growth "
                            'iteration): after the move the lamp stays on at the target for '
                            'this much lit time, then the photo and the answer; 0 = answer '
                            'once the move is done (the plant then grows until the next step)',
                            unit='s', bounds=Bounds(0.0, 1e7))
    lights_on: str = param('', 'photoperiod: the lamp may be lit from this local standard time '
                           '(a fixed UTC offset, never moved by DST); empty with lights_off = '
                           'no night', pattern=CLOCK, pattern_doc='HH:MM, or empty')
    lights_off: str = param('', 'photoperiod: the lamp is off from this local standard time '
                            '(earlier than lights_on: the window crosses midnight); a growth '
                            'period counts lit time only', pattern=CLOCK,
                            pattern_doc='HH:MM, or empty')
    utc_offset_h: float = param(0.0, 'local standard time minus UTC, all year', unit='h',
                                bounds=Bounds(-14.0, 14.0))

    def __post_init__(self) -> None:
        check(self)
        try:
            _ = self.photoperiod  # the window as a whole (both times or neither, a length)
        except ValueError as e:
            raise ParamError(str(e)) from None

    def step_time(self) -> dict[str, str]:
        """What decides a step's time on the rig, for the recording's metadata: a replay or a
        resumed run recomputes each step's growth period from it (``Photoperiod``)."""
        return {name: str(getattr(self, name)) for name in (
            'mode', 'growth_s', 'lights_on', 'lights_off', 'utc_offset_h')}

    @property
    def photoperiod(self) -> Photoperiod:
        """The lights-on window (``lights_on``, ``lights_off``, ``utc_offset_h``)."""
        return Photoperiod(self.lights_on, self.lights_off, self.utc_offset_h)


if __name__ == '__main__':
    print(schema.markdown_table(GantryParams))
