"""Keyboard teleop: the key mapping, the session logic on a fake, and a pty-driven smoke test."""

from __future__ import annotations

import curses
import json
import os
import pty
import select
import signal
import sys
import time

import pytest

from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import BEAM_ACTIONS, SPOT_ACTIONS
from growspace_sim.node.chamber_node import ChamberNode
from growspace_sim.node.fake import FakeTransport
from growspace_sim.node.params import NodeParams
from growspace_sim.ros import convert
from growspace_sim.ros import types
from growspace_sim.tools.teleop import QUIT, RESET, Teleop, key_to_command
from ros_helpers import Client, NodeProcess


# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

@pytest.mark.parametrize(('key', 'spot', 'name'), [
    (curses.KEY_LEFT, False, 'left'), (curses.KEY_RIGHT, False, 'right'),
    (ord('+'), False, 'wider'), ('=', False, 'wider'), ('-', False, 'narrower'),
    (' ', False, 'stay'), (curses.KEY_UP, True, 'up'), (curses.KEY_DOWN, True, 'down'),
    ('+', True, 'bigger'), (ord('-'), True, 'smaller'), (' ', True, 'stay'),
    (curses.KEY_LEFT, True, 'left'),
])
def test_keys_map_to_the_lights_actions(key: object, spot: bool, name: str) -> None:
    actions = SPOT_ACTIONS if spot else BEAM_ACTIONS
    assert key_to_command(key, spot) == actions.index(name)


def test_special_and_unknown_keys() -> None:
    assert key_to_command('r', False) == RESET and key_to_command(ord('q'), True) == QUIT
    assert key_to_command(curses.KEY_UP, False) is None  # a beam cannot move up
    assert key_to_command('x', False) is None and key_to_command(curses.KEY_F1, True) is None
    assert key_to_command(-1, False) is None


def test_teleop_says_ready_once_the_node_has_matched_it_both_ways() -> None:
    transport = FakeTransport()
    transport.unread.add(transport.resolve('light/command'))
    teleop = Teleop(transport)
    assert teleop.lines()[3] == 'waiting for the node...'
    teleop.status = 'teleop: no chamber in /growspace after 5 s'  # the watch, before discovery
    teleop._on_config(types.new('std_msgs/msg/String', data=json.dumps(
        {'mode': 'lockstep', 'config': {'challenge': 'control'}})), b'')
    assert teleop.lines()[3].startswith('teleop: no chamber')  # our commands have no reader
    transport.unread.clear()
    assert teleop.lines()[3] == 'ready: the node reads our keys'
    assert teleop.press(curses.KEY_RIGHT) and teleop.lines()[3] == 'sent right (step_id 1)'


def test_teleop_follows_step_ids_mode_and_light_kind() -> None:
    transport = FakeTransport()
    ChamberNode(transport, SimConfig(), NodeParams(seed=1))  # subscribes to the transport
    teleop = Teleop(transport)

    # The fake does not loop published messages back: hand the node's outputs to teleop.
    def relay() -> None:
        for topic, handler in (('step_result', teleop._on_result),
                               ('light/state', teleop._on_light),
                               ('chamber/config', teleop._on_config)):
            for msg, cdr in transport.published[transport.resolve(topic)]:
                handler(msg, cdr)
        transport.clear()
    relay()
    for key in (curses.KEY_RIGHT, curses.KEY_RIGHT, ord('+')):
        assert teleop.press(key)
        msg, cdr = transport.published[transport.resolve('light/command')][-1]
        transport.inject_raw('light/command', cdr)
        relay()
    assert teleop.last_step_id == 3 and teleop.last_result.step == 3
    for key in (curses.KEY_LEFT, curses.KEY_LEFT):  # a held key: sent before any answer
        assert teleop.press(key)
    ids = [m.step_id for m, _ in transport.published[transport.resolve('light/command')][-2:]]
    assert ids == [4, 5]
    for _, cdr in transport.published[transport.resolve('light/command')][-2:]:
        transport.inject_raw('light/command', cdr)
    relay()
    assert teleop.last_step_id == 5 and teleop.last_result.step == 5 and not \
        teleop.last_result.info
    assert teleop.press('r')
    msg, cdr = transport.published[transport.resolve('reset')][-1]
    transport.inject_raw('reset', cdr)
    relay()
    assert teleop.last_step_id == 0 and teleop.last_result.step == 0
    transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=2, challenge='shape'))
    relay()
    assert teleop.spot and teleop.press(curses.KEY_UP)
    assert transport.published[transport.resolve('light/command')][-1][0].action == \
        SPOT_ACTIONS.index('up')
    teleop._on_config(types.new('std_msgs/msg/String', data=json.dumps(
        {'mode': 'realtime', 'config': {'challenge': 'control'}})), b'')
    teleop.press(' ')
    last = transport.published[transport.resolve('light/command')][-1][0]
    assert last.step_id == 0 and last.mode == convert.MODE_DISCRETE
    assert not teleop.press('q')
    assert teleop.lines()[2].startswith('step 0  step_id 0')


def _read_until(fd: int, needle: bytes, timeout: float) -> bytes:
    out = b''
    deadline = time.monotonic() + timeout
    while needle not in out and time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 0.1)
        if ready:
            try:
                out += os.read(fd, 65536)
            except OSError:
                break
    return out


@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
def test_teleop_in_a_terminal_drives_the_node() -> None:
    namespace = '/teleop_smoke'
    node = NodeProcess('-p', 'seed:=2', namespace=namespace)
    pid, fd = pty.fork()
    if pid == 0:  # the child: teleop on a pseudo terminal
        os.environ['TERM'] = 'xterm'
        os.execv(sys.executable, [sys.executable, '-m', 'growspace_sim.tools.teleop', '--ros-args',
                                  '-r', f'__ns:={namespace}'])
    try:
        observer = Client(namespace, 'observer')
        try:
            observer.connect()
            # Teleop says when it and the node have matched both ways: a key before is lost.
            screen = _read_until(fd, b'ready: the node reads our keys', 60.0)
            assert b'ready: the node reads our keys' in screen, screen
            for expected in (1, 2):
                # Right arrow as xterm sends it in keypad (application) mode, which curses sets.
                os.write(fd, b'\x1bOC')
                deadline = time.monotonic() + 10.0
                while time.monotonic() < deadline and len(
                        [m for m in observer.results if m.step_id]) < expected:
                    observer.drain(0.1)
                    _read_until(fd, b'\0', 0.01)  # keep the pty drained
            assert [m.step_id for m in observer.results if m.step_id] == [1, 2]
        finally:
            observer.close()
        os.write(fd, b'q')
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
            _read_until(fd, b'\0', 0.1)
        assert done and os.waitstatus_to_exitcode(status) == 0
        pid = 0
    finally:
        if pid:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        os.close(fd)
        code, err = node.stop()
    assert code == 0, err


@pytest.mark.parametrize(('args', 'code', 'words'), [
    (['--help'], 0, 'usage: teleop'),
    ([], 2, 'teleop: needs an interactive terminal'),
    (['-p', 'x:=1'], 2, 'unrecognized arguments: -p x:=1'),
])
def test_teleop_without_a_terminal_says_so_in_one_line(args, code, words) -> None:
    import subprocess

    out = subprocess.run([sys.executable, '-m', 'growspace_sim.tools.teleop', *args],
                         stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60)
    assert out.returncode == code, out.stderr
    assert words in out.stdout + out.stderr and 'Traceback' not in out.stderr
