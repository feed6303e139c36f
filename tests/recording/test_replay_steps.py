"""``growspace-replay play --step-period``: a lockstep episode replayed step by step onto a node.

The node here is ``sim_node`` (the gantry's own replay is in test_gantry_ros.py): it answers
every request with a ``step_result``, and its recording shows in which order it handled them.
Started with another seed than the bag's, it places the light where the bag's episode began
only if the replay sends the episode's reset first.
"""

from __future__ import annotations

from pathlib import Path
import re
import signal
import time

import pytest

from growspace_sim.replay import Bag, main, read_episodes
from growspace_sim.replay.play import _wait_until
from ros_helpers import NodeProcess

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

BAG = Path(__file__).resolve().parents[2] / 'bags' / 'oracle_control_hard.mcap'


def lights(path: Path, namespace: str = '/growspace') -> dict[int, tuple[float, float]]:
    """step_id -> (x, width) of every light/state in a recording."""
    with Bag(path) as bag:
        return {m.step_id: (m.x, m.width) for m in (
            x.decode() for x in bag.messages([f'{namespace}/light/state']))}


def handled(path: Path) -> list[tuple[str, int]]:
    """(what, step_id) in the order the node handled them: commands, resets and results."""
    out = []
    with Bag(path) as bag:
        for m in bag.messages(['/growspace/light/command', '/growspace/reset',
                               '/growspace/step_result']):
            msg = m.decode()
            out.append((m.topic.rsplit('/', 1)[1], int(getattr(msg, 'step_id', 0))))
    return out


def sim_node(tmp_path: Path, *args: str) -> NodeProcess:
    return NodeProcess('-p', 'seed:=1', '-p', f'record_path:={tmp_path / "node.mcap"}', *args,
                       namespace='/growspace')


def test_a_lockstep_episode_replays_from_its_reset_one_step_at_a_time(tmp_path, capsys):
    node = sim_node(tmp_path)
    try:
        code = main(['play', str(BAG), '--step-period', '0.05', '--wait', '20',
                     '--step-timeout', '60'])
    finally:
        node.stop(signal.SIGINT)
    out, err = capsys.readouterr()
    assert code == 0, err
    assert '51 request(s) sent, 51 answered, 0 failed' in out
    assert 'step 50/50 (step_id 50): done' in err
    # The reset came first and placed the light as in the recording, and every command was
    # sent only once the step before it was answered.
    order = handled(tmp_path / 'node.mcap')
    start = order.index(('reset', 0))
    assert order[:start] == [('step_result', 0)]  # the node's own start-up episode
    assert order[start:start + 2] == [('reset', 0), ('step_result', 0)]
    assert order[start + 2:] == [x for k in range(1, 51)
                                 for x in (('command', k), ('step_result', k))]
    assert lights(tmp_path / 'node.mcap') == lights(BAG)


def test_chosen_steps_start_where_the_recording_had_the_light(tmp_path, capsys):
    node = sim_node(tmp_path)
    try:
        code = main(['play', str(BAG), '--step-period', '1.2', '--episode', '0',
                     '--start-step', '20', '--stop-step', '21', '--wait', '20',
                     '--step-timeout', '60'])
    finally:
        node.stop(signal.SIGINT)
    out, err = capsys.readouterr()
    assert code == 0, err
    order = handled(tmp_path / 'node.mcap')
    assert [s for what, s in order if what == 'command'] == [19, 20, 21]  # placement, steps
    expected, got = lights(BAG), lights(tmp_path / 'node.mcap')
    assert {k: got[k] for k in (0, 19, 20, 21)} == {k: expected[k] for k in (0, 19, 20, 21)}
    assert 'step 1/2 (step_id 20): done' in err and 'step 2/2 (step_id 21): done' in err


def test_a_long_step_period_says_when_the_next_request_goes():
    """Not silent: a wait of over a second is announced, then spun out (the transport's
    callbacks run meanwhile); a shorter one is not."""
    class Transport:
        spins = 0

        def spin_once(self, timeout_s: float) -> None:
            assert 0.0 <= timeout_s <= 0.1
            self.spins += 1
            time.sleep(timeout_s)  # as a spin with nothing to do

    said: list[str] = []
    transport = Transport()
    at = time.monotonic() + 3.0
    _wait_until(transport, at, 'step 2/2 (step_id 21)', said.append)
    assert time.monotonic() >= at and transport.spins >= 1
    assert len(said) == 1 and re.fullmatch(
        r'next: step 2/2 \(step_id 21\) at \d\d:\d\d:\d\d \(in [23] s\)', said[0]), said
    _wait_until(transport, time.monotonic() + 0.5, 'step 3/3', said.append)
    assert len(said) == 1


@pytest.mark.parametrize('keep_going', [False, True])
def test_a_step_that_fails_on_the_node_stops_the_replay_with_its_reason(tmp_path, capsys,
                                                                        keep_going):
    node = sim_node(tmp_path, '-p', 'episode_length:=10')  # steps 11.. are refused
    try:
        code = main(['play', str(BAG), '--step-period', '0', '--wait', '20',
                     '--step-timeout', '60'] + (['--keep-going'] if keep_going else []))
    finally:
        node.stop(signal.SIGINT)
    out, err = capsys.readouterr()
    assert code == 1
    assert 'step 11/50 (step_id 11): FAILED' in err and 'episode over' in err, err
    if keep_going:
        assert '51 request(s) sent, 11 answered, 40 failed' in out
    else:
        assert '12 request(s) sent, 11 answered, 1 failed; STOPPED: episode 0, step 11/50 ' \
            '(step_id 11) failed on the node: episode over' in out
        commands = [s for what, s in handled(tmp_path / 'node.mcap') if what == 'command']
        assert commands == list(range(1, 12))


def test_step_options_need_a_step_period(capsys):
    with pytest.raises(SystemExit):
        main(['play', str(BAG), '--episode', '0'])
    assert '--episode need(s) --step-period' in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(['play', str(BAG), '--step-period', '1', '--only', '/growspace/light/command'])
    assert '--only does not go with --step-period' in capsys.readouterr().err


def test_steps_the_recording_does_not_have_are_refused_before_anything_is_sent():
    from growspace_sim.replay import play_steps, ReplayError

    with Bag(BAG) as bag:
        assert [e.n_steps for e in read_episodes(bag)] == [50]
    with pytest.raises(ReplayError, match='has no step_id in 60..end'):
        play_steps(BAG, start_step=60)
    with pytest.raises(ReplayError, match='the recording has 1 episode'):
        play_steps(BAG, episode=1)


@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
def test_a_node_that_dies_mid_replay_stops_it_at_once(tmp_path):
    # The gantry's process died: no step_result will come, however long the step may take.
    import time

    from growspace_sim.replay import play_steps

    node = sim_node(tmp_path)
    killed_at = []

    def log(line: str) -> None:
        if 'step 3/50' in line and not killed_at:  # the node is answering: now it dies
            node.proc.kill()
            killed_at.append(time.monotonic())
    try:
        report = play_steps(BAG, step_period_s=0.5, step_timeout_s=600.0, log=log,
                            wait_for_subscribers_s=20.0)
    finally:
        node.stop()
    assert killed_at and 'the node left' in report.stopped, report
    assert time.monotonic() - killed_at[0] < 30  # NODE_GONE_S after the kill, not 600 s
