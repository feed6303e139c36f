"""One bad byte never costs a whole recording: every reader path skips what it cannot read.

A recording of three oracle episodes in small chunks (a few steps each) is damaged the ways
disks and copies damage files: a flipped byte inside the compressed data of the first, a middle
and the last chunk, a wrong chunk CRC, a flipped record length, and a file cut inside its
summary. Expected answers come from the intact file: which messages the damaged chunk held, and
which episodes those messages belong to.
"""

from __future__ import annotations

import io
from pathlib import Path
import struct

from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import breakup_chunk, StreamReader
import pytest

from growspace_sim import recording
from growspace_sim.agents import OracleAgent, play_episodes
from growspace_sim.core.config import SimConfig
from growspace_sim.node.episode_runner import EpisodeRunner
from growspace_sim.recording import McapRecorder
from growspace_sim.replay import Bag, export_episode, main, read_episodes, ReplayError, resimulate

CHUNK_SIZE = 64 * 1024  # bytes before compression: about three chamber steps a chunk
CHUNK_DATA = 1 + 8 + 8 + 8 + 8 + 4 + 4 + 4 + 8  # record prefix + chunk fields before the data
CHUNK_CRC = 1 + 8 + 8 + 8 + 8  # where the chunk's uncompressed CRC starts


@pytest.fixture(scope='module')
def intact(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp('damage') / 'intact.mcap'
    with McapRecorder(path, chunk_size=CHUNK_SIZE) as rec:
        runner = EpisodeRunner(SimConfig(challenge='control'), rec)
        for seed in (11, 12, 13):
            play_episodes(runner, OracleAgent(), [seed])
    return path


def chunks_of(path: Path) -> list:
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def messages_in(path: Path, index) -> list[Message]:
    with open(path, 'rb') as f:
        f.seek(index.chunk_start_offset)
        chunk = next(iter(StreamReader(io.BytesIO(f.read(index.chunk_length)), skip_magic=True,
                                       emit_chunks=True).records))
    return [r for r in breakup_chunk(chunk) if isinstance(r, Message)]


def total_messages(path: Path) -> int:
    with open(path, 'rb') as f:
        return make_reader(f).get_summary().statistics.message_count


def episodes_holding(path: Path, lost: list[Message]) -> list[int]:
    """Indexes of the intact file's episodes that the lost messages belong to."""
    with Bag(path) as bag:
        starts = [e.steps[0].log_time for e in read_episodes(bag)]
    return sorted({max([i for i, s in enumerate(starts) if s <= m.log_time], default=0)
                   for m in lost})


def damaged_copy(intact: Path, dst: Path, edit) -> Path:
    data = bytearray(intact.read_bytes())
    edit(data)
    dst.write_bytes(bytes(data))
    return dst


def flip_in_data(index):
    def edit(data: bytearray) -> None:
        data[index.chunk_start_offset + CHUNK_DATA + index.compressed_size // 2] ^= 0x55
    return edit


def wrong_crc(index):
    def edit(data: bytearray) -> None:
        at = index.chunk_start_offset + CHUNK_CRC
        crc, = struct.unpack_from('<I', data, at)
        struct.pack_into('<I', data, at, crc ^ 1)
    return edit


CASES = {  # name -> (which chunk: position in the file, how it is damaged)
    'first chunk, flipped byte': (0, flip_in_data),
    'middle chunk, flipped byte': (0.5, flip_in_data),
    'last chunk, flipped byte': (-1, flip_in_data),
    'middle chunk, wrong CRC': (0.3, wrong_crc),
}


def pick(chunks: list, where: float) -> object:
    return chunks[where] if isinstance(where, int) else chunks[int(where * len(chunks))]


@pytest.mark.parametrize('case', CASES)
def test_a_damaged_chunk_is_skipped_named_and_the_rest_read(intact, tmp_path, case):
    where, damage = CASES[case]
    chunks = chunks_of(intact)
    assert len(chunks) >= 20
    index = pick(chunks, where)
    lost = messages_in(intact, index)
    touched = episodes_holding(intact, lost)
    path = damaged_copy(intact, tmp_path / 'bad.mcap', damage(index))
    seen = []
    with Bag(path, on_damage=seen.append) as bag:
        kept = sum(1 for _ in bag.messages())
        assert kept == total_messages(intact) - len(lost)
        assert [(d.offset, d.end, d.what) for d in bag.damage] == [
            (index.chunk_start_offset, index.chunk_start_offset + index.chunk_length, 'chunk')]
        assert seen == bag.damage
        assert (bag.damage[0].start_time, bag.damage[0].end_time) == (
            index.message_start_time, index.message_end_time)
        episodes = read_episodes(bag)
    assert len(episodes) == 3
    assert [e.index for e in episodes if e.damaged] == touched
    assert all(str(index.chunk_start_offset) in ' '.join(episodes[i].damaged) for i in touched)

    report = resimulate(path)
    assert report.mismatch is None and not report.ok
    assert [line.split(':')[0] for line in report.unverified] == [f'episode {i}'
                                                                  for i in touched]
    assert report.episodes == 3 - len(touched)  # every other episode is still checked


@pytest.mark.parametrize('case', CASES)
def test_recover_keeps_every_readable_chunk_after_a_bad_one(intact, tmp_path, case):
    where, damage = CASES[case]
    chunks = chunks_of(intact)
    index = pick(chunks, where)
    lost = messages_in(intact, index)
    path = damaged_copy(intact, tmp_path / 'bad.mcap', damage(index))
    report = recording.recover(path, tmp_path / 'fixed.mcap')
    assert report.messages == total_messages(intact) - len(lost)
    assert report.chunks == len(chunks) - 1 and report.complete
    assert [d.offset for d in report.skipped] == [index.chunk_start_offset]
    with Bag(tmp_path / 'fixed.mcap') as bag:
        assert sum(1 for _ in bag.messages()) == report.messages
        # The recovered file keeps what was skipped (a metadata record), so readers of it
        # know its holes as readers of the damaged file did.
        assert [(d.offset, d.start_time) for d in bag.damage] == [
            (index.chunk_start_offset, index.message_start_time)]
        touched = [e.index for e in read_episodes(bag) if e.damaged]
    assert touched == episodes_holding(intact, lost)
    check = resimulate(tmp_path / 'fixed.mcap')
    assert check.mismatch is None and check.episodes == 3 - len(touched)
    assert len(check.unverified) == len(touched)


def test_a_broken_record_length_resumes_at_the_next_indexed_chunk(intact, tmp_path):
    chunks = chunks_of(intact)
    index = chunks[len(chunks) // 2]

    def edit(data: bytearray) -> None:  # the chunk's record length now runs past the file
        struct.pack_into('<Q', data, index.chunk_start_offset + 1, 2**40)

    path = damaged_copy(intact, tmp_path / 'bad.mcap', edit)
    with Bag(path) as bag:
        kept = sum(1 for _ in bag.messages())
        assert kept == total_messages(intact) - len(messages_in(intact, index))
        assert len(bag.damage) == 1 and bag.damage[0].offset == index.chunk_start_offset
        assert 'length field is damaged' in bag.damage[0].reason
    # Without a summary (the file also cut short) recover stops there and says why.
    cut = damaged_copy(path, tmp_path / 'cut.mcap', lambda data: data.__delitem__(
        slice(len(data) - 100, None)))
    report = recording.recover(cut, tmp_path / 'fixed.mcap')
    assert not report.complete and report.stopped_at == index.chunk_start_offset
    assert 'length field is damaged' in report.reason
    assert report.chunks == chunks.index(index)


def test_a_file_cut_inside_its_summary(intact, tmp_path):
    summary_start = _summary_start(intact)
    size = intact.stat().st_size
    path = damaged_copy(intact, tmp_path / 'cut.mcap',
                        lambda data: data.__delitem__(slice((summary_start + size) // 2, None)))
    with pytest.raises(ReplayError, match='growspace-replay recover'):
        Bag(path)
    report = recording.recover(path, tmp_path / 'fixed.mcap')
    assert report.complete and not report.skipped and report.reason == ''
    assert report.messages == total_messages(intact)
    assert resimulate(tmp_path / 'fixed.mcap').ok


def _summary_start(path: Path) -> int:
    data = path.read_bytes()
    # Footer: opcode, length, summary_start, summary_offset_start, summary_crc; then the magic.
    footer = len(data) - 8 - (1 + 8 + 8 + 8 + 4)
    return struct.unpack_from('<Q', data, footer + 9)[0]


@pytest.mark.slow
def test_cli_reports_damage_without_a_traceback(intact, tmp_path, capsys):
    chunks = chunks_of(intact)
    index = chunks[len(chunks) // 2]
    touched = episodes_holding(intact, messages_in(intact, index))
    path = damaged_copy(intact, tmp_path / 'bad.mcap', flip_in_data(index))

    assert main(['info', str(path)]) == 0
    out = capsys.readouterr()
    assert f'UNREADABLE chunk at bytes {index.chunk_start_offset}-' in out.out
    assert f'episode(s) touched: {", ".join(map(str, touched))}' in out.out

    assert main(['check', str(path)]) == 1
    out = capsys.readouterr()
    assert out.out.startswith(f'NOT VERIFIED: {len(touched)} episode(s) could not be checked')
    assert f'skipped unreadable chunk at byte {index.chunk_start_offset}' in out.err

    gif = tmp_path / 'e.gif'
    assert main(['export', str(path), str(gif), '--episode', str(touched[0])]) == 0
    out = capsys.readouterr()
    assert gif.exists() and f'episode {touched[0]} is incomplete' in out.err

    assert main(['recover', str(path), str(tmp_path / 'fixed.mcap')]) == 0
    out = capsys.readouterr()
    assert f'skipped unreadable chunk at byte {index.chunk_start_offset}' in out.out
    assert 'Traceback' not in out.out + out.err


def test_export_of_a_damaged_episode_warns_and_writes_what_it_read(intact, tmp_path):
    chunks = chunks_of(intact)
    index = chunks[len(chunks) // 2]
    episode = episodes_holding(intact, messages_in(intact, index))[0]
    path = damaged_copy(intact, tmp_path / 'bad.mcap', flip_in_data(index))
    warnings: list[str] = []
    n = export_episode(path, tmp_path / 'e.gif', episode=episode, progress=False,
                       warn=warnings.append)
    with Bag(intact) as bag:
        starts = [e.steps[0].log_time for e in read_episodes(bag)] + [2**63]
    image = _channel_id(intact, '/growspace/camera/image_raw')
    lost_images = sum(m.channel_id == image and starts[episode] <= m.log_time
                      < starts[episode + 1] for m in messages_in(intact, index))
    assert lost_images > 0 and n == 51 - lost_images
    assert any('skipped unreadable chunk' in w for w in warnings)
    assert any(f'episode {episode} is incomplete' in w for w in warnings)


def _channel_id(path: Path, topic: str) -> int:
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    return next(c.id for c in summary.channels.values() if c.topic == topic)
