"""sim_node recording end to end: an rclpy client drives the node, SIGTERM, then replay.

The node runs as the installed ``sim_node`` executable with ``record_path``; the recording it
leaves must re-simulate bit for bit and hold exactly what the client saw.
"""

from __future__ import annotations

from pathlib import Path
import subprocess

import pytest

from growspace_sim import replay
from growspace_sim.ros.interface import TOPICS
from ros_helpers import Client, NodeProcess

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

NAMESPACE = '/gs_recording'

EPISODE = 8  # steps per episode: short, the test is about wiring


def test_recording_of_a_lockstep_session_resimulates_and_matches_the_client(
        tmp_path: Path) -> None:
    path = tmp_path / 'node.mcap'
    node = NodeProcess('-p', 'seed:=4', '-p', f'episode_length:={EPISODE}', '-p',
                       f'record_path:={path}', namespace=NAMESPACE)
    answered = []  # (reset_id, step_id, step, reward, info) of every answer the client waited for
    try:
        client = Client(NAMESPACE)
        client.connect()
        first = client.reset(1, has_seed=True, seed=21)
        answered.append(first)
        step_id = 0
        while step_id < EPISODE + 1:  # one of the commands is rejected without a step
            step_id += 1
            action = 9 if step_id == 3 else step_id % 5  # 9: no such action
            answered.append(client.step(step_id, action))
        # Unseeded, so the random stream continues across the challenge switch.
        answered.append(client.reset(2, challenge='shape'))
        for step_id in range(1, EPISODE + 1):
            answered.append(client.step(step_id, step_id % 7))
        before = len(client.results)
        client.drain(0.3)  # a deliberate negative check: a late extra answer would come now
        late = client.results[before:]
        client.close()
    finally:
        try:
            code, err = node.stop()  # SIGTERM: the node finishes the file, exits 0
        except subprocess.TimeoutExpired:
            code, err = -1, 'the node did not stop'
    assert code == 0, err
    assert 'Traceback' not in err
    rejected = [m for m in answered if m.info]
    assert len(rejected) == 1 and 'action' in rejected[0].info and rejected[0].step == 2
    assert answered[-1].truncated and not late

    report = replay.resimulate(path)
    assert report.ok, report.mismatch
    assert (report.episodes, report.steps) == (3, 2 * EPISODE)  # the node's first one + 2

    info = replay.summary(path)
    assert [(e['reset_id'], e['challenge'], e['seed'], e['steps'], e['rejected'])
            for e in info['episodes']] == [(0, 'control', 4, 0, 0), (1, 'control', 21, EPISODE, 1),
                                           (2, 'shape', None, EPISODE, 0)]
    assert info['mode'] == 'lockstep' and info['seed'] == '4'
    # Exactly one StepResult per step and per rejected request, the ones the client saw. The
    # node's first is published at start, before or after the client matched: it may miss it.
    with replay.Bag(path) as bag:
        results = [key(m.decode()) for m in bag.messages([f'{NAMESPACE}/step_result'])]
        assert {t.topic for t in bag.topics.values()} == {
            t.name if t.name.startswith('/') else f'{NAMESPACE}/{t.name}' for t in TOPICS}
    seen = [key(m) for m in client.results]
    assert info['messages'][f'{NAMESPACE}/step_result'] == len(results) == 1 + len(answered)
    assert results[1:] == [key(m) for m in answered]
    assert seen in (results, results[1:])


def key(result: object) -> tuple:
    return (result.reset_id, result.step_id, result.step, result.reward, result.info)
