"""Keyboard teleop for a chamber: arrow keys move the light, +/- resize it, r resets.

Publishes ``LightCommand`` MODE_DISCRETE on ``light/command`` over rclpy. In lockstep mode it
sends the last step_id seen on ``step_result`` + 1; in realtime mode step_id 0. The mode and
light kind come from the node's latched ``chamber/config`` and from ``light/state``.

Usage: ``ros2 run growspace_sim teleop --ros-args -r __ns:=/chamber1`` or
``python -m growspace_sim.tools.teleop --ros-args -r __ns:=/chamber1``.
"""

from __future__ import annotations

from collections.abc import Sequence
import curses
import json
import secrets
import sys
from typing import Any

from growspace_sim import arguments
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import BEAM_ACTIONS, SPOT_ACTIONS
from growspace_sim.node.chamber_node import COMMAND_QOS, OBSERVATION_QOS
from growspace_sim.node.presence import ChamberWatch
from growspace_sim.ros import convert
from growspace_sim.ros import qos as ros_qos, types
from growspace_sim.ros.names import DEFAULT_NAMESPACE

QUIT, RESET = 'quit', 'reset'
HELP = ('arrows: move (up/down: spotlight)   +/-: wider/narrower (bigger/smaller)   '
        'space: stay   r: reset   q: quit')
_NAMED_KEYS = {curses.KEY_LEFT: 'left', curses.KEY_RIGHT: 'right', curses.KEY_UP: 'up',
               curses.KEY_DOWN: 'down'}
_CHAR_KEYS = {'+': 'grow', '=': 'grow', '-': 'shrink', '_': 'shrink', ' ': 'stay',
              'r': RESET, 'R': RESET, 'q': QUIT, 'Q': QUIT}


def key_to_command(key: int | str, spot: bool) -> int | str | None:
    """Map a key to a discrete action index of the light, RESET, QUIT, or None (ignored).

    Args:
        key: a curses key code (``curses.KEY_LEFT``...) or a one-character string.
        spot: True for the spotlight (shape challenge), False for the beam.
    """
    if isinstance(key, int):
        name = _NAMED_KEYS.get(key) or (_CHAR_KEYS.get(chr(key)) if 0 <= key < 256 else None)
    else:
        name = _CHAR_KEYS.get(key)
    if name in (QUIT, RESET) or name is None:
        return name
    actions = SPOT_ACTIONS if spot else BEAM_ACTIONS
    name = {'grow': 'bigger' if spot else 'wider',
            'shrink': 'smaller' if spot else 'narrower'}.get(name, name)
    return actions.index(name) if name in actions else None


WAITING = 'waiting for the node...'
READY = 'ready: the node reads our keys'


class Teleop:
    """The state of a teleop session, independent of the screen (tested without curses)."""

    def __init__(self, transport: Any) -> None:
        self.transport = transport
        self.send_command = transport.publisher(types.LIGHT_COMMAND, 'light/command',
                                                COMMAND_QOS)
        self.send_reset = transport.publisher(types.RESET_REQUEST, 'reset', COMMAND_QOS)
        transport.subscribe(types.STEP_RESULT, 'step_result', OBSERVATION_QOS, self._on_result)
        transport.subscribe(types.LIGHT_COMMAND, 'light/state', OBSERVATION_QOS, self._on_light)
        transport.subscribe(types.STRING, 'chamber/config', ros_qos.LATCHED,
                            self._on_config)
        self.last_step_id = 0
        self.last_result: Any = None
        self.spot = False
        self.mode = 'lockstep'
        self.status = WAITING  # or the chamber watch's warning, or what the last key did
        self.sent = False  # a key has sent a command or a reset
        self.config_seen = False

    def _on_result(self, msg: Any, _: bytes) -> None:
        self.last_result = msg
        if int(msg.step) == 0 and not msg.info:  # a new episode: the node counts from 1 again
            self.last_step_id = int(msg.step_id)
        else:  # never below an id already sent: a held key outruns the answers
            self.last_step_id = max(self.last_step_id, int(msg.step_id))

    def _on_light(self, msg: Any, _: bytes) -> None:
        self.spot = int(msg.mode) == convert.MODE_SPOT

    def _on_config(self, msg: Any, _: bytes) -> None:
        self.config_seen = True
        try:
            payload = json.loads(msg.data)
            self.mode = payload['mode']
            self.spot = SimConfig.from_dict(payload['config']).uses_spotlight
        except (ValueError, KeyError, TypeError):  # not a chamber's config: keep what we know
            pass

    def press(self, key: int | str) -> bool:
        """Handle a key; returns False when the user quits."""
        command = key_to_command(key, self.spot)
        if command == QUIT:
            return False
        if command is not None:
            self.sent = True
        if command == RESET:
            self.send_reset(types.new(types.RESET_REQUEST, reset_id=secrets.randbits(32)))
            self.status = 'reset sent'
        elif command is not None:
            step_id = self.last_step_id + 1 if self.mode == 'lockstep' else 0
            self.last_step_id = max(self.last_step_id, step_id)
            self.send_command(types.new(types.LIGHT_COMMAND, step_id=step_id,
                                        mode=convert.MODE_DISCRETE, action=command))
            names = SPOT_ACTIONS if self.spot else BEAM_ACTIONS
            self.status = f'sent {names[command]} (step_id {step_id})'
        return True

    def lines(self) -> list[str]:
        result = self.last_result
        shown = ('no step_result yet (is the node running in this namespace?)' if result is None
                 else f'step {result.step}  step_id {result.step_id}  reward '
                      f'{result.reward:.4f}  truncated {result.truncated}  {result.info}')
        light = 'spotlight' if self.spot else 'beam'
        return [f'GrowSpace teleop: {self.transport.resolve("light/command")} '
                f'({self.mode}, {light})', HELP, shown, self._status()]

    def _status(self) -> str:
        # Ready once both ways are matched: the node's latched config reached us (its writers
        # know our readers) and our command writer knows its reader (a key pressed before
        # would be lost: the node would never see that command). Until the first key, this
        # also replaces a no-chamber warning from before the chamber was found.
        if not self.sent and self.config_seen and \
                self.transport.has_subscribers('light/command'):
            return READY
        return self.status


def _loop(screen: Any, teleop: Teleop) -> None:
    curses.curs_set(0)
    screen.timeout(50)  # ms; keeps the screen fresh while messages arrive
    watch = ChamberWatch(teleop.transport, 'teleop', lambda text: setattr(teleop, 'status', text))
    while True:
        teleop.transport.spin_once(0.0)
        if teleop.config_seen:
            watch.seen()
        watch.check()
        screen.erase()
        for row, line in enumerate(teleop.lines()):
            screen.addnstr(row, 0, line, max(1, curses.COLS - 1))
        screen.refresh()
        key = screen.getch()
        if key != -1 and not teleop.press(key):
            return


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``teleop`` (``--ros-args -r __ns:=/chamber1`` picks the chamber)."""
    from rclpy.executors import ExternalShutdownException
    from rclpy.utilities import remove_ros_args

    from growspace_sim.node.main import ros_arguments_error
    from growspace_sim.node.rclpy_transport import RclpyTransport

    argv = sys.argv[1:] if argv is None else list(argv)
    error = ros_arguments_error(['teleop', *argv])
    if error is not None:  # a bad namespace, remap or params file: before any screen
        print(f'teleop: invalid ROS arguments: {error}', file=sys.stderr)
        return 2
    parser = arguments.Parser(
        prog='teleop', description=__doc__.split('\n')[0],
        epilog=f'Keys: {HELP}. ROS arguments come after --ros-args, e.g. '
               '--ros-args -r __ns:=/chamber1.')
    parser.parse_args(remove_ros_args(['teleop', *argv])[1:])  # --help; unknown flags: exit 2
    if not (sys.stdin.isatty() and sys.stdout.isatty()):
        print('teleop: needs an interactive terminal (it reads keys with curses); without one, '
              'publish commands with python -m growspace_sim.tools.pub', file=sys.stderr)
        return 2
    try:
        transport = RclpyTransport('growspace_teleop', DEFAULT_NAMESPACE,
                                   args=['teleop', *argv])
    except Exception as e:  # noqa: BLE001 - rcl's own message names the bad argument
        print(f'teleop: {e}', file=sys.stderr)
        return 2
    try:
        curses.wrapper(_loop, Teleop(transport))
    except curses.error as e:  # a terminal too small or without the capabilities curses needs
        print(f'teleop: the terminal cannot be used ({e})', file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        transport.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
