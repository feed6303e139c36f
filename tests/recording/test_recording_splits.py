"""Recordings split into files by size and duration, read back as one (issue 31, item 4)."""

from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader
import yaml

from growspace_sim import recording
from growspace_sim.agents import OracleAgent, play_episodes
from growspace_sim.core.config import SimConfig
from growspace_sim.node.episode_runner import EpisodeRunner
from growspace_sim.recording import McapRecorder, RecordingError, SplitRecorder
from growspace_sim.replay import Bag, compare, main as replay_main, ReplayError, resimulate
from growspace_sim.replay.episodes import read_episodes, summary

pytestmark = pytest.mark.slow  # records whole episodes (about 1 s each)


def _run(recorder, episodes: int = 3, seed: int = 5) -> None:
    with recorder:
        runner = EpisodeRunner(SimConfig(challenge='control'), recorder)
        play_episodes(runner, OracleAgent(), range(seed, seed + episodes))


def _messages(path: Path) -> list[tuple[str, bytes, int, int]]:
    with Bag(path) as bag:
        return [(m.topic, m.data, m.log_time, m.publish_time) for m in bag.messages()]


@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    """The same oracle run recorded into one file and split by size (about 12 files)."""
    root = tmp_path_factory.mktemp('splits')
    _run(McapRecorder(root / 'one.mcap'))
    _run(SplitRecorder(root / 'split', max_bytes=200_000))
    return root / 'one.mcap', root / 'split'


def test_split_by_size_reads_back_as_the_single_file_every_message_equal(runs):
    single, split = runs
    files = recording.split_files(split)
    assert [f.name for f in files] == [f'split_{i}.mcap' for i in range(len(files))]
    assert len(files) >= 4
    one = _messages(single)
    assert _messages(split) == one  # topic, bytes and both times of every message, in order
    with Bag(split) as bag:
        assert sum(i.count for i in bag.topics.values()) == len(one)
        assert bag.metadata[recording.METADATA_NAME]['seed'] == '5'


def test_every_split_file_is_complete_and_ends_on_a_step_result(runs):
    _, split = runs
    for path in recording.split_files(split):
        with AnyReader([path]) as reader:  # each file is a recording of its own
            topics = [c.topic for c, _, _ in reader.messages()]
        assert topics[-1].endswith('/step_result'), path  # never split inside a step
        with Bag(path) as bag:  # channels and metadata repeated in each file
            assert recording.METADATA_NAME in bag.metadata
            assert not bag.damage


def test_metadata_yaml_lists_the_files_rosbag2_style(runs):
    _, split = runs
    info = yaml.safe_load((split / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    files = recording.split_files(split)
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == [f.name for f in files]
    assert info['message_count'] == len(_messages(split))
    assert sum(t['message_count'] for t in info['topics_with_message_count']) == \
        info['message_count']


def test_replay_reads_a_split_recording_as_one(runs, tmp_path, capsys):
    single, split = runs
    report = resimulate(split)
    assert report.ok and report.episodes == 3 and report.steps == 150
    whole, parts = summary(single), summary(split)
    assert [e['return'] for e in parts['episodes']] == [e['return'] for e in whole['episodes']]
    assert parts['files'] == [f.name for f in recording.split_files(split)]
    result = compare(single, split)
    assert result.steps == 153 and result.within(0.0)  # the resets count too
    assert replay_main(['info', str(split)]) == 0
    assert f'{len(parts["files"])} files' in capsys.readouterr().out
    assert replay_main(['export', str(split), str(tmp_path / 'ep.gif'), '--episode', '2']) == 0
    assert (tmp_path / 'ep.gif').stat().st_size > 0


def test_split_by_duration_of_log_time(tmp_path):
    split = tmp_path / 'timed'
    _run(SplitRecorder(split, max_duration_s=1.0), episodes=1)  # sim time: 0.1 s a step
    files = recording.split_files(split)
    assert len(files) >= 5
    for path in files:
        with Bag(path) as bag:
            times = [m.log_time for m in bag.messages()]
        assert max(times) - min(times) < 1.0e9 + 0.1e9, path  # the batch that crosses goes on


def test_refuses_an_existing_directory_and_bad_limits(tmp_path):
    (tmp_path / 'taken').mkdir()
    with pytest.raises(RecordingError, match='exists already, not overwriting'):
        SplitRecorder(tmp_path / 'taken')
    with pytest.raises(RecordingError, match='max_bytes must be >= 0'):
        SplitRecorder(tmp_path / 'bad', max_bytes=-1)


def _cut_last_file(split: Path) -> Path:
    """A crash while the last file was open: its summary and footer never reached the disk."""
    last = recording.split_files(split)[-1]
    data = last.read_bytes()
    last.write_bytes(data[:len(data) // 2])
    return last


def test_damaged_last_split_is_recovered_in_place(tmp_path, capsys):
    split = tmp_path / 'crash'
    _run(SplitRecorder(split, max_bytes=200_000, chunk_size=16_384), episodes=2)
    before = _messages(split)
    last = _cut_last_file(split)
    with pytest.raises(ReplayError, match=f'growspace-replay recover {split}` repairs'):
        Bag(split)
    assert replay_main(['recover', str(split)]) == 0
    assert 'the damaged original is' in capsys.readouterr().out
    assert last.with_name(last.name + '.damaged').exists()
    after = _messages(split)
    assert 0 < len(after) < len(before) and after == before[:len(after)]
    with Bag(split) as bag:
        assert bag.damage  # the lost tail is named, as for a recovered single file
        episodes = read_episodes(bag)
    assert episodes[0].n_steps == 50 and not episodes[0].damaged
    assert replay_main(['recover', str(split)]) == 0  # nothing left to do
    assert 'nothing to recover' in capsys.readouterr().out


def test_append_repairs_then_continues_with_the_next_file(tmp_path):
    split = tmp_path / 'resumed'
    _run(SplitRecorder(split, max_bytes=200_000), episodes=1)
    n = len(recording.split_files(split))
    _cut_last_file(split)
    with SplitRecorder(split, append=True) as rec:
        assert rec.path.name == f'resumed_{n}.mcap'
    with Bag(split) as bag:
        assert len(bag.files) == n + 1
