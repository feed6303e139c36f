"""Re-segmentation of a recorded hardware bag (issue 22, item 7): a bad threshold found after a
week of growth must not cost the week.

The rig's recordings are made here as gantry_node records them (tests/camera_bags.py: the photo
twin through camera_node's capture service, the real message classes and the project's writer),
once with camera_node's defaults and once with a threshold that sees no plant. Expected answers
come from those recordings: re-segmenting the bad one with the defaults must give the good one,
and the good one with the bad threshold the bad one, message for message.
"""

from __future__ import annotations

import json
import shlex

import cv2
import numpy as np
import pytest

from camera_bags import Refused, rig_recording
from growspace_camera.cli import main
from growspace_camera.photo_export import CAPTION_PX
from growspace_camera.recorded import RecordedSteps
from growspace_camera.resegment import RESEGMENT_METADATA
from growspace_camera.settings import PIPELINE_FIELDS
from growspace_sim.core.config import SimConfig
from growspace_sim.recording import McapRecorder
from growspace_sim.recording.scan import RECOVERY_METADATA
from growspace_sim.replay.bag import Bag
from growspace_sim.ros import types
from growspace_sim.simulation import Simulation
from test_bag_damage import _channel_id, chunks_of, damaged_copy, flip_in_data, messages_in
from test_readme import documented, ROOT

BAD = 0.9  # min_greenness: above every plant's excess green, so no photo shows a plant
EPISODES = [7, None]  # the second reset continues the first one's random stream
STEPS = 3
PHOTOS = len(EPISODES) * (STEPS + 1)
CAMERA = ('camera/image_raw', 'plant/state', 'camera/measurement', 'step_result')


# Most tests read the module's rig recording, made in about 10 s: none in the quick tier.
pytestmark = pytest.mark.slow


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    folder = tmp_path_factory.mktemp('rig')
    good = rig_recording(folder / 'good.mcap', EPISODES, STEPS)
    bad = rig_recording(folder / 'bad.mcap', EPISODES, STEPS, min_greenness=BAD)
    return good, bad


def read(path):
    with Bag(path) as bag:
        return list(bag.messages()), bag.metadata


def comparable(msg):
    """What a measurement must reproduce: all of it but the time the pipeline took."""
    if msg.topic.endswith('camera/measurement'):
        decoded = msg.decode()
        decoded.processing_s = 0.0
        return msg.topic, msg.log_time, msg.publish_time, types.serialize(decoded, msg.typename)
    return msg.topic, msg.log_time, msg.publish_time, msg.data


def assert_same_messages(a, b):
    ours, theirs = read(a)[0], read(b)[0]
    assert [m.topic for m in ours] == [m.topic for m in theirs]
    for x, y in zip(ours, theirs):
        assert comparable(x) == comparable(y), x.topic


def decoded(path, rel):
    return [m.decode() for m in read(path)[0] if m.topic == f'/growspace/{rel}']


def test_the_recorded_settings_give_the_recorded_measurements(bags, tmp_path, capsys):
    good, _ = bags
    out = tmp_path / 'same.mcap'
    before = good.read_bytes()
    assert main(['resegment', str(good), str(out)]) == 0
    assert f'{PHOTOS} photo(s) measured again, {PHOTOS} read (recorded: {PHOTOS}), 0 step(s) ' \
        f'changed' in capsys.readouterr().out
    assert good.read_bytes() == before  # the input is only read
    assert_same_messages(good, out)
    metadata = read(out)[1]
    assert metadata['growspace'] == read(good)[1]['growspace']
    record = metadata[RESEGMENT_METADATA]
    assert record['source'] == str(good) and record['base'] == 'camera_node defaults'
    assert len(record['source_sha256']) == 64 and record['photos'] == str(PHOTOS)
    assert set(json.loads(record['settings'])) == set(PIPELINE_FIELDS)


def test_a_bad_threshold_after_a_week_is_undone(bags, tmp_path, capsys):
    good, bad = bags
    assert all(m.info.startswith('error: camera: no_plant: ') and m.reward == 0.0
               for m in decoded(bad, 'step_result'))
    out = tmp_path / 'fixed.mcap'
    assert main(['resegment', str(bad), str(out)]) == 0
    assert f'{PHOTOS} read (recorded: 0), {PHOTOS} step(s) changed' in capsys.readouterr().out
    # Observations and plant states appear where the bad threshold gave none, in the gantry's
    # order: exactly the recording the right threshold would have made.
    assert_same_messages(good, out)


def test_a_raised_threshold_shrinks_the_plants_and_changes_the_rewards(bags, tmp_path):
    good, bad = bags
    out = tmp_path / 'raised.mcap'
    assert main(['resegment', str(good), str(out), '--set', 'min_greenness=0.15']) == 0
    old, new = decoded(good, 'camera/measurement'), decoded(out, 'camera/measurement')
    assert all(m.threshold == 0.06 for m in old)  # the default floor held on every photo
    assert all(m.ok and m.threshold == 0.15 for m in new)
    assert all(n.plant_pixels < o.plant_pixels for o, n in zip(old, new))
    results = decoded(out, 'step_result')
    assert [r.reward for r in results] == [m.reward for m in new]
    assert [r.reward for r in results] != [r.reward for r in decoded(good, 'step_result')]
    # Everything else is the recording's own bytes.
    keep = [(m.topic, m.log_time, m.data) for m in read(good)[0]
            if m.topic.rsplit('/growspace/')[-1] not in CAMERA]
    assert keep == [(m.topic, m.log_time, m.data) for m in read(out)[0]
                    if m.topic.rsplit('/growspace/')[-1] not in CAMERA]
    assert len(keep) == len(read(good)[0]) - 4 * PHOTOS
    # A threshold above the plant: nothing measured, as the camera with it answered live.
    none = tmp_path / 'none.mcap'
    assert main(['resegment', str(good), str(none), '--set', f'min_greenness={BAD}']) == 0
    assert_same_messages(bad, none)


def test_settings_come_from_a_params_file_and_a_resegmented_recording(bags, tmp_path, capsys):
    good, _ = bags
    params = tmp_path / 'camera.yaml'
    params.write_text('camera_node:\n  ros__parameters:\n    source: /dev/video0\n'
                      '    min_greenness: 0.15\n')
    first, second = tmp_path / 'first.mcap', tmp_path / 'second.mcap'
    assert main(['resegment', str(good), str(first), '--params', str(params)]) == 0
    assert main(['resegment', str(first), str(second)]) == 0  # its own settings, recorded
    assert "the settings recorded in first.mcap (growspace_resegment), with {'min_greenness': " \
        "0.15}" in capsys.readouterr().out
    assert_same_messages(first, second)


@pytest.mark.parametrize('args, message', [
    (['--set', 'min_greenness=2'], '--set: min_greenness must be in [0.0, 1.0], got 2.0.'),
    (['--set', 'dark_level=dark'], "--set: dark_level must be a number, got 'dark'."),
    (['--set', 'min_greenness'], "--set 'min_greenness': expected NAME=VALUE"),
    (['--set', 'fps=30'], "--set: 'fps' is not a setting of the camera pipeline; allowed: "
                          'markers, lens, pixel_size_m, min_greenness'),
    (['--set', 'markers=/nowhere.yaml'], "markers = '/nowhere.yaml' cannot be read"),
    (['--set', 'lens=/nowhere.yaml'], "lens = '/nowhere.yaml' cannot be read"),
    (['--params', '/nowhere.yaml'], "argument --params: '/nowhere.yaml': the file does not "
                                    'exist'),
])
def test_bad_settings_are_one_line_naming_the_setting_the_value_and_what_is_allowed(
        bags, tmp_path, capsys, args, message):
    out = tmp_path / 'out.mcap'
    try:
        code = main(['resegment', str(bags[0]), str(out), *args])
    except SystemExit as e:  # what the command line alone rules out, argparse refuses
        code = e.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and err.count('\n') == 1 and 'Traceback' not in err
    assert not out.exists()


def test_a_recording_without_photos_or_an_existing_output_is_refused(bags, tmp_path, capsys):
    sample = ROOT / 'bags' / 'oracle_control_easy.mcap'  # the simulator's: no camera/photo
    assert main(['resegment', str(sample), str(tmp_path / 'out.mcap')]) == 2
    assert 'has no /growspace/camera/photo topic: not a recording of the rig' in \
        capsys.readouterr().err
    assert not (tmp_path / 'out.mcap').exists()
    good = bags[0]
    before = good.read_bytes()
    assert main(['resegment', str(good), str(good)]) == 2
    assert 'exists already, not overwriting (it is the input)' in capsys.readouterr().err
    assert good.read_bytes() == before
    assert main(['export', str(sample), str(tmp_path / 'seen')]) == 2
    assert 'no /growspace/camera/photo topic' in capsys.readouterr().err


def test_an_episode_whose_reset_is_not_in_the_file_is_not_measured(bags, tmp_path):
    good, _ = bags
    cut = tmp_path / 'no_second_reset.mcap'
    messages, metadata = read(good)
    configs = [m for m in messages if m.topic == '/growspace/chamber/config']
    with Bag(good) as bag, McapRecorder(cut) as rec:
        channels = {t: rec.add_channel(t, i.typename, i.qos) for t, i in bag.topics.items()}
        rec.add_metadata('growspace', metadata['growspace'])
        for m in messages:
            if m is not configs[-1]:  # the second reset's
                rec.write(channels[m.topic], m.data, m.log_time, m.publish_time)
    out = tmp_path / 'out.mcap'
    assert main(['resegment', str(cut), str(out)]) == 0
    results = decoded(out, 'step_result')
    assert all(not r.info for r in results[:STEPS + 1])
    assert all(r.info.startswith('error: camera: bad_input: ') and 'reset_id 2' in r.info
               and r.reward == 0.0 for r in results[STEPS + 1:])
    assert len(decoded(out, 'camera/image_raw')) == STEPS + 1


def rewritten_configs(src, dst, change):
    """A copy of ``src`` with each chamber/config payload passed through ``change``."""
    messages, metadata = read(src)
    with Bag(src) as bag, McapRecorder(dst) as rec:
        channels = {t: rec.add_channel(t, i.typename, i.qos) for t, i in bag.topics.items()}
        rec.add_metadata('growspace', metadata['growspace'])
        for m in messages:
            data = m.data
            if m.topic == '/growspace/chamber/config':
                payload = change(json.loads(m.decode().data))
                data = types.serialize(types.new(types.STRING, data=json.dumps(payload)),
                                       types.STRING)
            rec.write(channels[m.topic], data, m.log_time, m.publish_time)
    return dst


def test_an_unseeded_episode_after_a_refused_reset_is_measured_with_its_recorded_target(
        tmp_path, capsys):
    # The gantry refused reset 2: no chamber/config for it, and nothing changed. Reset 3
    # continues the stream of reset 1.
    episodes = [7, Refused(None), None]
    rig = rig_recording(tmp_path / 'rig.mcap', episodes, STEPS)
    assert [m.reset_id for m in decoded(rig, 'step_result') if m.info] == [2]
    photos = 2 * (STEPS + 1)
    out = tmp_path / 'out.mcap'
    assert main(['resegment', str(rig), str(out)]) == 0
    assert f'{photos} photo(s) measured again, {photos} read (recorded: {photos}), 0 step(s) ' \
        f'changed' in capsys.readouterr().out
    assert_same_messages(rig, out)  # the camera's live numbers, from the recorded target
    with Bag(rig) as bag:
        recorded = [p for step in RecordedSteps(bag) for p in step.photos]
    sim = Simulation(SimConfig())
    for seed in (7, None):
        sim.reset(seed=seed)
    assert {p.target.point for p in recorded[STEPS + 1:]} == {sim.chamber.target}


    # The same run as the gantry recorded it before it recorded its target (its refused reset
    # had drawn from the stream): the stream is laid out again, cannot know of the refusal,
    # and says so instead of measuring with a wrong target.
    old = rig_recording(tmp_path / 'old.mcap', episodes, STEPS, target=False)
    assert 'target' not in json.loads(decoded(old, 'chamber/config')[-1].data)
    legacy = tmp_path / 'legacy.mcap'
    assert main(['resegment', str(old), str(legacy)]) == 0
    results = [r for r in decoded(legacy, 'step_result') if r.reset_id != 2]
    assert all(not r.info for r in results[:STEPS + 1])
    assert all(r.info.startswith('error: camera: bad_input: episode 2: its target was not laid '
                                 'out as the gantry did (episode 4 recorded, 3 here')
               and 'predates the target' in r.info and r.reward == 0.0
               for r in results[STEPS + 1:])


def test_a_shape_recording_is_measured_again_against_its_recorded_digit(tmp_path, capsys):
    rig = rig_recording(tmp_path / 'shape.mcap', [7, None], 1, challenge='shape')
    masks = [json.loads(c.data)['target']['mask'] for c in decoded(rig, 'chamber/config')]
    res = SimConfig(challenge='shape').resolution
    assert all(len(m) == res and {len(r) for r in m} == {res} and '1' in ''.join(m)
               for m in masks)
    out = tmp_path / 'out.mcap'
    assert main(['resegment', str(rig), str(out)]) == 0
    assert '4 photo(s) measured again, 4 read (recorded: 4), 0 step(s) changed' in \
        capsys.readouterr().out
    assert_same_messages(rig, out)


def test_a_recorded_target_that_cannot_be_read_leaves_its_episode_unmeasured(bags, tmp_path):
    def spoil(payload):
        if payload['reset_id'] == 2:
            payload['target'] = {'x': 'far', 'z': 0.5}
        return payload
    bad = rewritten_configs(bags[0], tmp_path / 'spoilt.mcap', spoil)
    out = tmp_path / 'out.mcap'
    assert main(['resegment', str(bad), str(out)]) == 0
    results = decoded(out, 'step_result')
    assert all(not r.info for r in results[:STEPS + 1])
    assert all(r.info.startswith('error: camera: bad_input: episode 2: its chamber/config cannot '
                                 'be read: target must be {"x": <m>, "z": <m>} (finite) or ')
               and '"x": "far"' in r.info for r in results[STEPS + 1:])


def test_a_damaged_recording_is_read_around_and_a_cut_one_sent_to_recover(tmp_path, capsys):
    # One message per chunk: a photo's chunk holds nothing else, whatever the photos' sizes.
    small = rig_recording(tmp_path / 'small.mcap', [7], STEPS, chunk_size=1)
    photo_id, *others = (_channel_id(small, f'/growspace/{rel}')
                         for rel in ('camera/photo', 'step_result', 'chamber/config'))
    held = [(c, {m.channel_id for m in messages_in(small, c)}) for c in chunks_of(small)]
    photo = next(c for c, ids in held  # a chunk with a photo, not its step_result or reset
                 if photo_id in ids and not ids.intersection(others))
    damaged = damaged_copy(small, tmp_path / 'damaged.mcap', flip_in_data(photo))
    out = tmp_path / 'out.mcap'
    assert main(['resegment', str(damaged), str(out)]) == 0
    captured = capsys.readouterr()
    assert f'skipped unreadable chunk at byte {photo.chunk_start_offset}' in captured.err
    assert '1 step(s) whose photo is unreadable now unmeasured' in captured.out
    with Bag(out) as bag:
        assert RECOVERY_METADATA in bag.metadata and len(bag.damage) == 1  # the hole, named
        results = [m.decode() for m in bag.messages(['/growspace/step_result'])]
    lost = [r for r in results if r.info]
    assert len(results) == STEPS + 1 and len(lost) == 1
    assert lost[0].info.startswith('error: camera: no_photo: the photo of this step is in an '
                                   'unreadable part') and lost[0].reward == 0.0
    data = small.read_bytes()
    (tmp_path / 'cut.mcap').write_bytes(data[:len(data) * 2 // 3])
    assert main(['resegment', str(tmp_path / 'cut.mcap'), str(tmp_path / 'x.mcap')]) == 2
    assert 'growspace-replay recover' in capsys.readouterr().err
    assert not (tmp_path / 'x.mcap').exists()


def test_the_steps_of_a_recording_read_back_with_their_context(bags):
    with Bag(bags[0]) as bag:
        photos = [p for step in RecordedSteps(bag) for p in step.photos]
    # Episode 0 is the gantry's start-up layout (no move, so no photo).
    assert [(p.episode, p.step) for p in photos] == \
        [(e, s) for e in range(1, len(EPISODES) + 1) for s in range(STEPS + 1)]
    assert all(p.light is not None and p.result is not None and not p.unknown for p in photos)
    # Each photo's target is the one the camera was sent: the unseeded episode's is the
    # continued stream's, not the first episode's.
    sim = Simulation(SimConfig())
    for episode, seed in enumerate(EPISODES, start=1):
        sim.reset(seed=seed)
        assert {p.target.point for p in photos if p.episode == episode} == {sim.chamber.target}
    assert photos[0].target.point != photos[-1].target.point


def test_export_draws_what_the_camera_saw_on_every_photo(bags, tmp_path, capsys):
    good, bad = bags
    seen = tmp_path / 'seen'
    assert main(['export', str(good), str(seen), '--format', 'png', '--scale', '0.5']) == 0
    assert f'wrote {PHOTOS} picture(s) to {seen} ({PHOTOS} with a plant read)' in \
        capsys.readouterr().out
    files = sorted(seen.iterdir())
    assert [f.name for f in files] == [f'{i:05d}_ep{e:03d}_step{s:04d}.png' for i, (e, s) in
                                       enumerate((e, s) for e in range(1, len(EPISODES) + 1)
                                                 for s in range(STEPS + 1))]
    photos = decoded(good, 'camera/photo')
    for path, photo in zip(files, photos):
        picture = cv2.imread(str(path), cv2.IMREAD_COLOR)
        bgr = cv2.imdecode(np.asarray(photo.data, np.uint8), cv2.IMREAD_COLOR)
        plain = cv2.resize(bgr, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
        assert picture.shape == (plain.shape[0] + CAPTION_PX, *plain.shape[1:])
        drawn = picture[:-CAPTION_PX][np.any(picture[:-CAPTION_PX] != plain, axis=2)]
        b, g, r = drawn.astype(int).T
        assert np.sum((g >= 153) & (g - np.maximum(b, r) > 60)) > 20  # the mask, tinted green
        assert np.sum((b == 255) & (r == 255) & (g == 0)) > 200  # four markers outlined
    assert main(['export', str(good), str(seen)]) == 2  # not into a folder that holds files
    assert 'is not an empty folder' in capsys.readouterr().err
    with pytest.raises(SystemExit) as exited:
        main(['export', str(good), str(tmp_path / 'x'), '--scale', '3'])
    assert exited.value.code == 2
    assert 'argument --scale: 3 is not allowed; expected' in capsys.readouterr().err


def test_the_documented_lines_run_as_written(bags, tmp_path, monkeypatch, capsys):
    lines = [line for _, line in documented() if line.startswith(
        ('growspace-camera resegment ', 'growspace-camera export '))]
    assert any(' resegment ' in line for line in lines) and \
        any(' export ' in line for line in lines)
    (tmp_path / 'rig.mcap').write_bytes(bags[0].read_bytes())
    monkeypatch.chdir(tmp_path)
    for line in lines:
        assert main(shlex.split(line)[1:]) == 0, (line, capsys.readouterr())
    assert list(tmp_path.glob('*/*.jpg'))  # export's pictures
