"""camera_node's logic over the in-process transport: the capture service a gantry calls (here a
stand-in client), the realtime loop, the status, and what a missing camera does. No device is
ever opened: sources are the photo twin, files and paths that do not exist.
"""

from __future__ import annotations

from pathlib import Path
import re
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from growspace_camera import messages as wire
from growspace_camera.capture import Camera, DeviceSettings, DeviceSource, open_source, \
    PhotoSource, Shot, VideoSource
from growspace_camera.main import build
from growspace_camera.measure import Target
from growspace_camera.pipeline import Pipeline
from growspace_camera.settings import CameraParams, layout_from_dict, load_layout
from growspace_camera.twin import PhotoTwin
from growspace_sim.core.config import SimConfig
from growspace_sim.node.fake import FakeTransport
from growspace_sim.node.params import as_values, ParamError
from growspace_sim.ros import convert, types
from growspace_sim.ros.interface import config_json
from growspace_sim.simulation import Simulation

STAMP = 1_700_000_000_123_456_789


def node_on(tmp_path, **params):
    transport = FakeTransport('growspace_camera', '/gs')
    values = as_values(SimConfig(), CameraParams(**params))
    return transport, build(transport, values)


def capture(transport, sim: Simulation, step: int, step_id: int):
    """What the gantry will do after a move: call camera/capture with the step's context."""
    c = sim.chamber
    request = wire.capture_request(config_json(sim.cfg, sim.seed), c.light.copy(), STAMP,
                                   step_id, step, Target(c.target, c.target_mask))
    # Through the codec both ways, as over rclpy.
    request = types.deserialize(types.serialize(request, f'{wire.CAPTURE}_Request'),
                                f'{wire.CAPTURE}_Request')
    response = transport.services['camera/capture'](request)
    return types.deserialize(types.serialize(response, f'{wire.CAPTURE}_Response'),
                             f'{wire.CAPTURE}_Response')


@pytest.mark.slow
def test_a_capture_answers_with_the_steps_outputs_stamped_as_asked(tmp_path):
    transport, node = node_on(tmp_path, source='twin', twin_seed=3)
    sim = Simulation(SimConfig(challenge='control', setting='easy'))
    outcome = sim.reset(seed=21)
    reply = capture(transport, sim, step=0, step_id=0)
    m = reply.measurement
    assert m.ok, m.error
    assert abs(m.reward - outcome.reward) < 0.05
    for msg in (reply.observation, reply.plant, reply.photo, m):
        assert convert.to_ns(msg.header.stamp) == STAMP
    assert (reply.observation.height, reply.observation.width, reply.observation.encoding) == \
        (84, 84, 'rgb8')
    image = convert.image_from_msg(reply.observation)
    assert np.array_equal(image[..., 0], sim.observe()[..., 0])  # the target, from the task
    assert len(reply.plant.node_x) >= 2 and reply.plant.parent[0] == -1
    assert reply.photo.format == 'jpeg' and bytes(reply.photo.data[:3]) == b'\xff\xd8\xff'
    assert list(m.markers_seen) == [0, 1, 2, 3] and m.tips == len(reply.plant.tips)
    # the twin grows its plant under the light it is told of, one step per request step
    for step in (1, 2, 3):
        sim.step()
        reply = capture(transport, sim, step=step, step_id=step)
        assert reply.measurement.ok and reply.plant.step == step
    status = transport.messages('camera/status')[-1].status[0]
    assert status.level == 0 and status.hardware_id == 'twin'


def test_a_bad_request_is_an_error_answer_naming_the_field(tmp_path):
    transport, _ = node_on(tmp_path, source='twin')
    sim = Simulation(SimConfig())
    sim.reset(seed=1)
    request = wire.capture_request(config_json(sim.cfg, 1), sim.chamber.light.copy(), STAMP, 1,
                                   1, Target(sim.chamber.target))
    request.light.mode = convert.MODE_DISCRETE
    reply = transport.services['camera/capture'](request)
    assert not reply.measurement.ok and reply.measurement.error_code == 'bad_input'
    assert 'light.mode must be 0 (beam) or 1 (spot)' in reply.measurement.error
    assert reply.measurement.reward == 0.0 and len(reply.plant.node_x) == 0
    assert len(reply.observation.data) == 0 and len(reply.photo.data) == 0
    request.light.mode, request.config = convert.MODE_BEAM, '{"config": {"challenge": "x"}}'
    reply = transport.services['camera/capture'](request)
    assert 'config must be a chamber/config JSON payload' in reply.measurement.error
    assert any('refused' in w for w in transport.warnings)


def test_a_refusal_names_its_reason_in_the_answer_and_on_camera_status(tmp_path):
    from test_camera_vision import stem_painted_out

    cfg = SimConfig(challenge='control', setting='hard')
    sim = Simulation(cfg)
    sim.reset(seed=11)
    oracle = cfg.task.oracle()
    for _ in range(12):
        sim.apply_discrete(oracle.act(sim.chamber))
        sim.step()
    shot = PhotoTwin(load_layout()).photo(sim.chamber, seed=4)
    fit = Pipeline().measure(shot.bgr, cfg, sim.chamber.light.copy(),
                             Target(sim.chamber.target), sim.chamber.steps).fit.fit
    photos = tmp_path / 'shots'
    photos.mkdir()
    cv2.imwrite(str(photos / 'a.png'), stem_painted_out(shot.bgr, fit, cfg.chamber_width))
    transport, _ = node_on(tmp_path, source=str(photos))
    reply = capture(transport, sim, step=sim.chamber.steps, step_id=7)
    m = reply.measurement
    assert not m.ok and m.error_code == 'unexplained' and 'reach no stem base' in m.error
    assert m.reward == 0.0 and len(reply.plant.node_x) == 0
    status = transport.messages('camera/status')[-1].status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == 1 and 'unexplained: ' in status.message
    assert values['last_error'].startswith('unexplained: ') and float(values['unexplained']) > 0.5


def test_segmentation_is_drawn_only_while_someone_subscribes(tmp_path):
    transport, _ = node_on(tmp_path, source='twin')
    sim = Simulation(SimConfig())
    sim.reset(seed=2)
    transport.unread.add(transport.resolve('camera/segmentation'))
    capture(transport, sim, 0, 0)
    assert transport.messages('camera/segmentation') == []
    transport.unread.clear()
    capture(transport, sim, 0, 0)
    (picture,) = transport.messages('camera/segmentation')
    assert (picture.width, picture.height, picture.encoding) == (960, 540, 'rgb8')


def test_a_missing_device_is_a_status_and_a_retry_not_a_traceback(tmp_path):
    missing = '/dev/video97'  # checked before OpenCV is asked: no device is opened
    if Path(missing).exists():
        pytest.skip(f'{missing} exists here')
    transport, node = node_on(tmp_path, source=missing, retry_max_s=2.0)
    assert isinstance(node.camera.source, DeviceSource)
    sim = Simulation(SimConfig())
    sim.reset(seed=3)
    reply = capture(transport, sim, 0, 0)
    m = reply.measurement
    assert not m.ok and m.error_code == 'no_photo' and 'does not exist' in m.error
    assert 'next try in' in m.error and len(reply.photo.data) == 0
    status = transport.messages('camera/status')[-1].status[0]
    assert status.level == 2 and status.message.startswith('offline:')
    lost = [w for w in transport.warnings if 'retrying' in w]
    assert len(lost) == 1 and 'retrying every 0.5-2 s' in lost[0]


class CountingSource(PhotoSource):
    """A folder of photos that notes when it was asked to open."""

    def __init__(self, folder: str, clock) -> None:  # noqa: ANN001
        super().__init__(folder, loop=True)
        self.clock, self.tries = clock, []

    def open(self) -> dict[str, str]:
        self.tries.append(self.clock.t)
        return super().open()


def test_camera_backs_off_and_comes_back(tmp_path):
    clock = SimpleNamespace(t=0.0)
    warnings, infos = [], []
    folder = tmp_path / 'shots'
    source = CountingSource(str(folder), clock)
    camera = Camera(source, warnings.append, infos.append, lambda: clock.t, retry_max_s=5.0)
    shot = Shot(SimConfig(), None, 0)
    for t in np.arange(0.0, 12.0, 0.25):
        clock.t = float(t)
        assert camera.read(shot) is None
    assert source.tries[:5] == [0.0, 0.5, 1.5, 3.5, 8.5]  # 0.5, 1, 2, 5 s apart
    assert len(warnings) == 1 and f'folder {folder} does not exist' in warnings[0]
    folder.mkdir()
    sim = Simulation(SimConfig())
    sim.reset(seed=4)
    (folder / 'a.jpg').write_bytes(PhotoTwin(load_layout(), size=(320, 180)).photo(
        sim.chamber, 1).jpeg)
    clock.t = 100.0
    frame = camera.read(shot)
    assert frame is not None and frame.jpeg[:3] == b'\xff\xd8\xff' and camera.online
    assert any('open' in line for line in infos)


def test_file_sources_loop_or_end(tmp_path):
    sim = Simulation(SimConfig())
    sim.reset(seed=5)
    twin = PhotoTwin(load_layout(), size=(320, 180))
    for k in range(2):
        (tmp_path / f'{k}.jpg').write_bytes(twin.photo(sim.chamber, k).jpeg)
    shot = Shot(SimConfig(), None, 0)
    once = Camera(open_source(str(tmp_path / '*.jpg'), DeviceSettings(), loop=False),
                  lambda s: None, lambda s: None)
    assert [once.read(shot) is not None for _ in range(3)] == [True, True, False]
    assert once.ended and 'no more photos' in once.failure
    looping = Camera(open_source(str(tmp_path), DeviceSettings(), loop=True),
                     lambda s: None, lambda s: None)
    assert all(looping.read(shot) is not None for _ in range(5))
    assert isinstance(open_source(str(tmp_path / 'run.mp4'), DeviceSettings(), True),
                      VideoSource)
    assert isinstance(open_source('3', DeviceSettings(), True), DeviceSource)


def test_an_unreadable_file_is_skipped_once_and_the_run_ends_at_the_last_photo(tmp_path):
    sim = Simulation(SimConfig())
    sim.reset(seed=5)
    twin = PhotoTwin(load_layout(), size=(320, 180))
    (tmp_path / 'a.jpg').write_bytes(twin.photo(sim.chamber, 0).jpeg)
    (tmp_path / 'b.jpg').write_bytes(b'')  # empty: OpenCV's own message is '!buf.empty()'
    (tmp_path / 'c.png').write_bytes(b'not a png at all')
    (tmp_path / 'd.jpg').write_bytes(twin.photo(sim.chamber, 1).jpeg)
    shot = Shot(SimConfig(), None, 0)
    warnings = []
    once = Camera(open_source(str(tmp_path), DeviceSettings(), loop=False,
                              warn=warnings.append), warnings.append, lambda s: None)
    got = [once.read(shot) for _ in range(4)]
    assert [f is not None for f in got] == [True, True, False, False]
    assert once.ended and 'no more photos' in once.failure
    assert len(warnings) == 2 and all('buf' not in w for w in warnings), warnings
    assert 'b.jpg is not a photo OpenCV can read: the file is empty' in warnings[0]
    assert 'c.png is not a photo OpenCV can read (16 bytes' in warnings[1]
    warnings.clear()
    looping = Camera(open_source(str(tmp_path), DeviceSettings(), loop=True,
                                 warn=warnings.append), warnings.append, lambda s: None)
    frames = [looping.read(shot) for _ in range(6)]
    assert all(f is not None for f in frames) and len(warnings) == 2  # said once per file
    assert [f.jpeg for f in frames[:2]] == [f.jpeg for f in frames[2:4]]


def test_a_reopened_folder_goes_on_after_its_last_photo(tmp_path):
    sim = Simulation(SimConfig())
    sim.reset(seed=5)
    twin = PhotoTwin(load_layout(), size=(320, 180))
    photos = [twin.photo(sim.chamber, k).jpeg for k in range(3)]
    for k, jpeg in enumerate(photos):
        (tmp_path / f'{k}.jpg').write_bytes(jpeg)
    source = PhotoSource(str(tmp_path), loop=False)
    source.open()
    assert source.read(Shot(SimConfig(), None, 0)).jpeg == photos[0]
    source.close()  # as a Camera does when the source is lost
    source.open()
    assert source.read(Shot(SimConfig(), None, 0)).jpeg == photos[1]


def test_a_folder_of_nothing_readable_ends_with_that_reason(tmp_path):
    (tmp_path / 'a.jpg').write_bytes(b'')
    warnings = []
    camera = Camera(open_source(str(tmp_path), DeviceSettings(), loop=True,
                                warn=warnings.append), warnings.append, lambda s: None)
    assert camera.read(Shot(SimConfig(), None, 0)) is None
    assert camera.ended and 'none of its files is a photo OpenCV can read' in camera.failure


def test_missing_path_missing_folder_and_unreadable_file_are_three_messages(tmp_path, capsys):
    (tmp_path / 'bad.jpg').write_bytes(b'\x00' * 40)
    shot = Shot(SimConfig(), None, 0)

    def failure(spec: str) -> str:
        camera = Camera(open_source(spec, DeviceSettings(), loop=False), lambda s: None,
                        lambda s: None)
        assert camera.read(shot) is None
        return camera.failure

    missing = failure(str(tmp_path / 'gone.jpg'))
    folder = failure(str(tmp_path / 'gone') + '/')
    folder_glob = failure(str(tmp_path / 'gone' / '*.jpg'))
    unreadable = failure(str(tmp_path / 'bad.jpg'))
    assert missing == f'photo {tmp_path}/gone.jpg does not exist'
    assert folder == f'folder {tmp_path}/gone/ does not exist'
    assert folder_glob.startswith(f'folder {tmp_path}/gone (of ')
    assert unreadable.endswith('none of its files is a photo OpenCV can read')
    # The console tool: a missing path or a folder is refused with its arguments, before any
    # photo is measured (exit 2); a file OpenCV cannot read is named with what it holds.
    from growspace_camera.cli import main
    for path, words in ((tmp_path / 'gone.jpg', 'the file does not exist'),
                        (tmp_path, 'is not a file')):
        with pytest.raises(SystemExit) as exit_:
            main(['measure', str(path)])
        assert exit_.value.code == 2 and words in capsys.readouterr().err
    code = main(['measure', str(tmp_path / 'bad.jpg')])
    lines = capsys.readouterr().out.splitlines()
    assert code == 1 and lines == [
        f'NOT MEASURED: {tmp_path}/bad.jpg is not a photo OpenCV can read (40 bytes, '
        "starting b'\\x00\\x00\\x00\\x00\\x00\\x00\\x00\\x00')"]


def test_realtime_publishes_a_measured_photo_per_tick(tmp_path):
    transport, node = node_on(tmp_path, source='twin', mode='realtime', rate_hz=2.0, seed=9)
    transport.advance(1.01)
    images = transport.messages('camera/image_raw')
    measurements = transport.messages('camera/measurement')
    assert len(images) == len(measurements) == 2
    assert all(m.ok for m in measurements), [m.error for m in measurements]
    assert len(transport.messages('plant/state')) == 2
    assert len(transport.messages('camera/photo')) == 2
    # a light/state moves the observation's light
    light = types.new(types.LIGHT_COMMAND, mode=convert.MODE_BEAM, x=0.2, width=0.1)
    transport.inject('light/state', light)
    transport.advance(0.5)
    blue = convert.image_from_msg(transport.messages('camera/image_raw')[-1])[..., 2]
    assert np.flatnonzero(blue[40])[[0, -1]].tolist() == [15, 24]


@pytest.mark.parametrize('params, match', [
    ({'mode': 'burst'}, re.escape("mode must be one of ('lockstep', 'realtime'), got 'burst'")),
    ({'source': ' '}, "source must be 'twin', a V4L2 device"),
    ({'width': 0}, r'width must be in \[16, 8192\], got 0'),
    ({'exposure': -2.0}, r'exposure must be in \[1.0, 1000000.0\] or -1, got -2.0'),
    ({'pixel_size_m': 0.5}, r'pixel_size_m must be in \[0.0005, 0.02\], got 0.5'),
    ({'frame_id': 'a b'}, 'frame_id must be a frame name'),
    ({'max_loops': -1}, r'max_loops must be in \[0, 100000\], got -1'),
    ({'max_share_gap': 1.5}, r'max_share_gap must be in \[0.0, 1.0\], got 1.5'),
    ({'max_float_m': -0.1}, r'max_float_m must be in \[0.0, 1.0\], got -0.1'),
])
def test_bad_parameters_are_refused_with_the_name_value_and_range(params, match):
    with pytest.raises(ParamError, match=match):
        CameraParams(**params)


def test_camera_nodes_defaults_are_the_pipelines():
    # Each pipeline setting has its default twice (camera_node's parameter, the pipeline's
    # dataclass); the bench measures Pipeline() as "what camera_node starts with".
    from growspace_camera.markers import MarkerLayout
    from growspace_camera.pipeline import PipelineParams

    assert CameraParams().pipeline(MarkerLayout()) == PipelineParams(MarkerLayout())
    rig = CameraParams(max_loops=40, max_share_gap=0.4, max_unexplained=0.3,
                       max_float_m=0.1).pipeline(MarkerLayout())
    assert (rig.max_loops, rig.max_share_gap, rig.max_unexplained, rig.max_float_m) == \
        (40, 0.4, 0.3, 0.1)


def test_bad_marker_files_are_refused_naming_the_file_and_key(tmp_path):
    with pytest.raises(ParamError, match='cannot be read'):
        load_layout(str(tmp_path / 'nope.yaml'))
    with pytest.raises(ParamError, match='needs exactly the keys'):
        layout_from_dict({'dictionary': 'DICT_4X4_50', 'ids': [0, 1, 2, 3]})
    good = {'dictionary': 'DICT_4X4_50', 'side_m': 0.06, 'ids': [0, 1, 2, 3],
            'centres_m': [[0, 0], [1, 0], [1, 1], [0, 1]]}
    assert layout_from_dict(good).centres[2] == (1.0, 1.0)
    with pytest.raises(ParamError, match='4 different ids'):
        layout_from_dict({**good, 'ids': [0, 0, 1, 2]})
    with pytest.raises(ParamError, match=r'centres_m must be a list of \[x, z\] pairs'):
        layout_from_dict({**good, 'centres_m': [[0, 0], [1], [1, 1], [0, 1]]})
    path = Path(tmp_path / 'm.yaml')
    path.write_text('dictionary: [')
    with pytest.raises(ParamError, match='is not YAML'):
        load_layout(str(path))
