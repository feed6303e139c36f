"""The simulator resumes a recorded episode bit for bit (issue 31, item 4).

A chamber that recorded k steps and then "crashed" is started again from its recording: the
recording re-simulated to its last step, then the same actions. The whole recording, read back
as one, must equal an uninterrupted run's message for message, every step exactly once.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from growspace_sim.core.config import SimConfig
from growspace_sim.node.episode_runner import EpisodeRunner
from growspace_sim.node.main import load_resume_point
from growspace_sim.node.params import ParamError
from growspace_sim.recording import SplitRecorder
from growspace_sim.replay import Bag, resimulate, resume_point
from growspace_sim.ros import types

pytestmark = pytest.mark.slow  # re-simulates recorded episodes (1-2 s)

SEEDS = (7, 8)  # two episodes: the crash falls in the first
CRASH_AFTER = 17  # steps of the first episode recorded before the crash
ACTIONS = np.random.default_rng(0).integers(0, 5, size=(len(SEEDS), 50))


def _play(runner: EpisodeRunner, episode: int, first_step: int) -> None:
    for action in ACTIONS[episode, first_step:]:
        runner.step(int(action))


def _messages(path):
    with Bag(path) as bag:
        return [(m.topic, m.data, m.log_time, m.publish_time) for m in bag.messages()]


def _step_ids(path) -> list[tuple[int, int]]:
    with Bag(path) as bag:
        return [(int(m.decode().reset_id), int(m.decode().step_id))
                for m in bag.messages() if m.typename == types.STEP_RESULT]


@pytest.fixture
def uninterrupted(tmp_path):
    path = tmp_path / 'whole'
    with SplitRecorder(path, max_bytes=150_000) as rec:
        runner = EpisodeRunner(SimConfig(challenge='control'), rec)
        for episode, seed in enumerate(SEEDS):
            runner.reset(seed=seed)
            _play(runner, episode, 0)
    return path


def test_resumed_run_equals_the_uninterrupted_one_bit_for_bit(tmp_path, uninterrupted):
    (tmp_path / 'live').mkdir()
    live, crashed = tmp_path / 'live' / 'run', tmp_path / 'run'  # same name: the files' names
    rec = SplitRecorder(live, max_bytes=150_000, chunk_size=8_192)
    runner = EpisodeRunner(SimConfig(challenge='control'), rec)
    runner.reset(seed=SEEDS[0])
    for action in ACTIONS[0, :CRASH_AFTER]:
        runner.step(int(action))
    rec.flush()
    # The crash: the files as a hard kill leaves them (the open one without its summary).
    shutil.copytree(live, crashed)
    rec.close()

    point = load_resume_point(str(crashed))  # what sim_node -p resume_path:= does first
    assert (point.steps, point.last_step_id, point.episode_over) == (CRASH_AFTER, CRASH_AFTER,
                                                                     False)
    assert point.report.steps == CRASH_AFTER and point.report.mismatch is None
    with SplitRecorder(crashed, max_bytes=150_000, append=True) as rec:
        runner = EpisodeRunner(SimConfig(challenge='control'), rec)
        runner.resume(point)
        _play(runner, 0, CRASH_AFTER)
        runner.reset(seed=SEEDS[1])
        _play(runner, 1, 0)

    assert _messages(crashed) == _messages(uninterrupted)  # every byte and stamp, in order
    ids = _step_ids(crashed)
    assert ids == _step_ids(uninterrupted)
    for reset_id in {r for r, _ in ids}:
        assert [s for r, s in ids if r == reset_id] == list(range(51))  # each step once
    assert resimulate(crashed).ok
    assert any(p.name.endswith('.damaged') for p in crashed.iterdir())  # the repaired file


def test_resume_observation_is_the_recorded_last_image(tmp_path, uninterrupted):
    runner = EpisodeRunner(SimConfig(challenge='control'))
    observation = runner.resume(resume_point(uninterrupted))
    with Bag(uninterrupted) as bag:
        images = [m for m in bag.messages() if m.typename == types.IMAGE]
    from growspace_sim.ros import convert
    assert np.array_equal(observation, convert.image_from_msg(images[-1].decode()))
    with pytest.raises(ValueError, match='episode over'):  # the recording ended its episode
        runner.step(0)


def test_resume_path_errors_name_the_parameter_and_value(tmp_path):
    not_mcap = tmp_path / 'notes.mcap'
    not_mcap.write_text('not a recording')
    for path, why in ((tmp_path / 'missing', 'does not exist'), (not_mcap, 'not an MCAP file')):
        with pytest.raises(ParamError, match=rf"resume_path = '{path}' cannot be resumed: "
                                             rf'.*{why}'):
            load_resume_point(str(path))
    assert load_resume_point('') is None
