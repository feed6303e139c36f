"""growspace-replay compare: the applied light of two runs, step by step (sim vs gantry)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from growspace_sim.agents import OracleAgent, play_episodes
from growspace_sim.core.config import SimConfig
from growspace_sim.node.episode_runner import EpisodeRunner
from growspace_sim.recording import McapRecorder
from growspace_sim.replay import Bag, compare, main
from growspace_sim.ros import types


def record(path: Path, challenge: str, seeds=(4, 5)) -> None:
    with McapRecorder(path) as rec:
        runner = EpisodeRunner(SimConfig(challenge=challenge), rec)
        for seed in seeds:
            play_episodes(runner, OracleAgent(), [seed])


def shifted_copy(src: Path, dst: Path, step_id: int, dx: float) -> None:
    """A copy whose second episode's light/state at ``step_id`` is ``dx`` m further right."""
    with Bag(src) as bag, McapRecorder(dst) as out:
        channels = {t: out.add_channel(t, i.typename, i.qos) for t, i in bag.topics.items()}
        for name, data in bag.metadata.items():
            out.add_metadata(name, data)
        resets = 0
        for m in bag.messages():
            data = m.data
            if m.topic.endswith('/step_result') and m.decode().step == 0:
                resets += 1
            if m.topic.endswith('/light/state') and resets == 2:
                msg = m.decode()
                if msg.step_id == step_id:
                    msg.x += dx
                    data = types.serialize(msg, m.typename)
            out.write(channels[m.topic], data, m.log_time, m.publish_time)


@pytest.mark.parametrize('challenge,fields', [('control', ['x', 'width']),
                                              ('shape', ['x', 'z', 'radius'])])
def test_the_same_run_twice_differs_by_nothing(tmp_path, challenge, fields):
    record(tmp_path / 'a.mcap', challenge)
    record(tmp_path / 'b.mcap', challenge)
    result = compare(tmp_path / 'a.mcap', tmp_path / 'b.mcap')
    assert result.steps == 2 * 51 and not result.unmatched and not result.skipped
    assert list(result.errors) == fields
    assert all(e.max_abs == 0.0 and e.rms == 0.0 for e in result.errors.values())


def test_one_shifted_step_is_found_with_its_size_and_place(tmp_path):
    record(tmp_path / 'a.mcap', 'control')
    shifted_copy(tmp_path / 'a.mcap', tmp_path / 'b.mcap', step_id=7, dx=0.003)
    result = compare(tmp_path / 'a.mcap', tmp_path / 'b.mcap')
    x = result.errors['x']
    assert x.max_abs == pytest.approx(0.003) and x.worst == 'episode 1, step_id 7'
    assert x.rms == pytest.approx(0.003 / math.sqrt(102))
    assert result.errors['width'].max_abs == 0.0
    assert main(['compare', str(tmp_path / 'a.mcap'), str(tmp_path / 'b.mcap'),
                 '--tolerance-mm', '3.5']) == 0
    assert main(['compare', str(tmp_path / 'a.mcap'), str(tmp_path / 'b.mcap'),
                 '--tolerance-mm', '2.5']) == 1


def test_steps_only_one_side_holds_are_listed(tmp_path):
    record(tmp_path / 'a.mcap', 'control', seeds=(4, 5))
    record(tmp_path / 'b.mcap', 'control', seeds=(4,))
    result = compare(tmp_path / 'a.mcap', tmp_path / 'b.mcap')
    assert result.steps == 51 and result.unmatched == ['episode 1: only in A']


def test_a_challenge_with_another_light_is_not_compared(tmp_path, capsys):
    record(tmp_path / 'a.mcap', 'control', seeds=(4,))
    record(tmp_path / 'b.mcap', 'shape', seeds=(4,))
    result = compare(tmp_path / 'a.mcap', tmp_path / 'b.mcap')
    assert result.steps == 0 and len(result.skipped) == 51
    assert 'light mode 0 in A, 1 in B' in result.skipped[0]
    assert main(['compare', str(tmp_path / 'a.mcap'), str(tmp_path / 'b.mcap')]) == 1
    assert 'no step of A and B could be compared' in capsys.readouterr().err


def hardware_like_copy(src: Path, dst: Path, failed: set[int]) -> None:
    """A copy as the gantry records a replay whose steps ``failed`` were refused: their
    step_result has an error and no observation before it, and ``step`` counts the answered
    steps only."""
    with Bag(src) as bag, McapRecorder(dst) as out:
        channels = {t: out.add_channel(t, i.typename, i.qos) for t, i in bag.topics.items()}
        for name, data in bag.metadata.items():
            out.add_metadata(name, data)
        held = []  # a step's observations, written with its result unless it failed
        for m in bag.messages():
            if m.topic.endswith(('/light/state', '/camera/image_raw', '/plant/state')):
                held.append(m)
                continue
            data = m.data
            if m.topic.endswith('/step_result'):
                msg = m.decode()
                if msg.step_id in failed:
                    msg.info = 'error: superseded by a newer command'
                    held = []
                msg.step -= sum(1 for f in failed if f <= msg.step_id)
                data = types.serialize(msg, m.typename)
            for h in held:
                out.write(channels[h.topic], h.data, h.log_time, h.publish_time)
            held = []
            out.write(channels[m.topic], data, m.log_time, m.publish_time)


def test_runs_are_matched_by_step_id_not_by_order(tmp_path):
    """Steps 1-4 refused on the hardware side: every later step is still compared with its own
    step_id (not with the one four steps earlier), and the missing ones are listed."""
    record(tmp_path / 'a.mcap', 'control', seeds=(4,))
    hardware_like_copy(tmp_path / 'a.mcap', tmp_path / 'b.mcap', {1, 2, 3, 4})
    result = compare(tmp_path / 'a.mcap', tmp_path / 'b.mcap')
    assert result.steps == 51 - 4
    assert all(e.max_abs == 0.0 for e in result.errors.values()), result.errors
    assert result.unmatched == ['episode 0, step_id 1-4: only in A']
