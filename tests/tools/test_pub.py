"""``python -m growspace_sim.tools.pub``: every reader of the topic gets every message."""

from __future__ import annotations

import threading
import time

import pytest

from growspace_sim.node.rclpy_transport import RclpyTransport
from growspace_sim.ros import types
from growspace_sim.ros.interface import COMMAND_QOS
from growspace_sim.tools import pub

# Each publish waits for the readers to settle (seconds): none in the quick tier.
pytestmark = pytest.mark.slow

TOPIC = '/gs_pub_test/light/command'
DEADLINE_S = 30.0  # generous: the machine may be loaded


class Reader:
    """A subscriber node of its own (its own participant, as another process's would be)."""

    def __init__(self, name: str) -> None:
        self.transport = RclpyTransport(name, '/gs_pub_test')
        self.steps: list[int] = []
        self.transport.subscribe(types.LIGHT_COMMAND, TOPIC, COMMAND_QOS,
                                 lambda msg, _cdr: self.steps.append(int(msg.step_id)))
        self._stop = False
        self._thread = threading.Thread(target=self.transport.spin,
                                        args=(lambda: self._stop,), daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop = True
        self._thread.join(timeout=DEADLINE_S)
        self.transport.close()


@pytest.fixture
def readers():
    made = [Reader('pub_test_sim'), Reader('pub_test_recorder')]
    try:
        yield made
    finally:
        for reader in made:
            reader.close()


def test_every_reader_gets_every_message_and_pub_names_them(readers, capsys):
    """Two readers (sim_node and a recorder beside it): pub used to wait for the first reader
    it matched and publish then, so the other one missed commands (8 of 10 in issue 33; here one
    of the two got 4 of 10, in each of two runs)."""
    published = 6
    for step in range(1, published + 1):
        assert pub.main([TOPIC, types.LIGHT_COMMAND, f'{{step_id: {step}}}', '--wait', '20']) == 0
        out = capsys.readouterr().out
        assert f'published on {TOPIC} to 2 readers' in out, out
        assert '/gs_pub_test/pub_test_sim' in out and '/gs_pub_test/pub_test_recorder' in out
        assert 'acknowledged by every reader' in out, out
    deadline = time.monotonic() + DEADLINE_S
    while any(len(r.steps) < published for r in readers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert [r.steps for r in readers] == [list(range(1, published + 1))] * 2


def test_a_named_node_is_waited_for(readers, capsys):
    """``--node`` names a reader that must be there; one that never comes is one line, exit 1,
    and nothing is published."""
    assert pub.main([TOPIC, types.LIGHT_COMMAND, '{step_id: 7}', '--node', 'pub_test_sim',
                     '--node', '/gs_pub_test/pub_test_recorder', '--wait', '20']) == 0
    assert 'to 2 readers' in capsys.readouterr().out
    # (the wait runs out whatever happens: long enough for pub's new participant to discover
    # both readers on a loaded machine, which the line lists)
    assert pub.main([TOPIC, types.LIGHT_COMMAND, '{step_id: 8}', '--node', 'nobody',
                     '--wait', '10']) == 1
    captured = capsys.readouterr()
    assert captured.err.strip().splitlines() == [
        f'pub: node nobody does not read {TOPIC} after 10 s (its readers: '
        '/gs_pub_test/pub_test_recorder, /gs_pub_test/pub_test_sim); nothing published'], \
        captured.err
    deadline = time.monotonic() + DEADLINE_S
    while any(len(r.steps) < 1 for r in readers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert [r.steps for r in readers] == [[7], [7]]
