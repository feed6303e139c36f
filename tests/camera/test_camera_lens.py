"""A calibrated lens: OpenCV's model round trips, the rectified view sampled through it, a
ROS calibration file read, and a twin photo with barrel distortion measured as a distortion-free
one is (files and arrays only)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import yaml

from growspace_camera.errors import BAD_INPUT, CameraError
from growspace_camera.lens import Lens
from growspace_camera.markers import MarkerLayout
from growspace_camera.measure import Target
from growspace_camera.pipeline import Pipeline
from growspace_camera.settings import CameraParams, load_lens
from growspace_camera.twin import optics, PhotoTwin, Variation
from growspace_camera.twin.variation import draw_rig
from growspace_sim.node.params import ParamError
from test_camera_vision import grown_by_oracle

MATRIX = np.array([[1100.0, 0.0, 960.0], [0.0, 1080.0, 540.0], [0.0, 0.0, 1.0]])
BARREL = np.array([-0.2, 0.05, 0.001, -0.002, 0.01])
LENS = Lens(MATRIX, BARREL, (1920, 1080))
PIXELS = np.array([[0.0, 0.0], [1919.0, 1079.0], [100.0, 900.0], [960.0, 540.0]])


def test_distorting_and_undistorting_round_trip_and_the_centre_stays():
    assert np.abs(LENS.ideal(LENS.distorted(PIXELS)) - PIXELS).max() < 1e-3
    assert LENS.distorted(np.array([[960.0, 540.0]])) == pytest.approx(np.array([[960, 540]]))
    # Barrel: a point near the corner is pulled in towards the centre.
    corner = LENS.distorted(np.array([[1900.0, 1060.0]]))[0]
    assert 960 < corner[0] < 1900 and 540 < corner[1] < 1060


def test_the_sampling_maps_put_each_output_pixel_where_the_lens_puts_its_point():
    to_ideal = np.array([[2.1, 0.1, 300.0], [0.05, -2.0, 900.0], [1e-5, 2e-5, 1.0]])
    to_sampled = np.array([[0.5, 0.0, -50.0], [0.0, 0.5, -20.0], [0.0, 0.0, 1.0]])
    map_x, map_y = LENS.sample_maps(to_ideal, (336, 300), to_sampled)
    out = np.array([[0, 0], [335, 299], [100, 200], [17, 250]])
    ideal = np.c_[out, np.ones(len(out))] @ to_ideal.T
    want = np.c_[LENS.distorted(ideal[:, :2] / ideal[:, 2:]), np.ones(len(out))] @ to_sampled.T
    got = np.c_[map_x[out[:, 1], out[:, 0]], map_y[out[:, 1], out[:, 0]]]
    assert np.abs(got - want[:, :2]).max() < 1e-3


@pytest.mark.parametrize('matrix, coefficients, size, message', [
    (MATRIX[:2], BARREL, (1920, 1080), 'camera_matrix must be 3 x 3'),
    (-MATRIX, BARREL, (1920, 1080), 'fx, fy > 0'),
    (MATRIX, BARREL[:3], (1920, 1080), r'distortion must hold 4, 5, 8, 12, 14 finite'),
    (MATRIX, np.r_[BARREL[:4], np.nan], (1920, 1080), 'finite'),
    (MATRIX, BARREL, (0, 1080), r'size must be \(width, height\)'),
])
def test_a_bad_lens_is_refused_naming_what_is_wrong(matrix, coefficients, size, message):
    with pytest.raises(ValueError, match=message):
        Lens(matrix, coefficients, size)


def calibration_yaml(path, **changes) -> str:
    """A calibration file as ROS's camera_calibration writes it."""
    data = {'image_width': 1920, 'image_height': 1080, 'camera_name': 'rig',
            'camera_matrix': {'rows': 3, 'cols': 3, 'data': MATRIX.reshape(-1).tolist()},
            'distortion_model': 'plumb_bob',
            'distortion_coefficients': {'rows': 1, 'cols': 5, 'data': BARREL.tolist()},
            'rectification_matrix': {'rows': 3, 'cols': 3, 'data': np.eye(3).reshape(-1).tolist()},
            'projection_matrix': {'rows': 3, 'cols': 4, 'data': [0.0] * 12}}
    data.update(changes)
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_a_ros_calibration_file_is_read_and_reaches_the_pipeline(tmp_path):
    lens = load_lens(calibration_yaml(tmp_path / 'rig.yaml'))
    assert np.array_equal(lens.camera_matrix, MATRIX) and np.array_equal(lens.distortion, BARREL)
    assert lens.size == (1920, 1080)
    params = CameraParams(lens=str(tmp_path / 'rig.yaml')).pipeline(MarkerLayout())
    assert params.lens.size == (1920, 1080)
    assert CameraParams().pipeline(MarkerLayout()).lens is None


@pytest.mark.parametrize('changes, message', [
    ({'distortion_model': 'equidistant'}, "distortion_model must be plumb_bob or "
                                          "rational_polynomial .*got 'equidistant'"),
    ({'camera_matrix': None}, 'needs image_width, image_height, camera_matrix.data'),
    ({'distortion_coefficients': {'data': [0.1, 0.2]}}, 'distortion must hold'),
])
def test_a_bad_calibration_file_is_one_message_naming_the_file(tmp_path, changes, message):
    path = calibration_yaml(tmp_path / 'bad.yaml', **changes)
    with pytest.raises(ParamError, match=f"lens = '{path}'.*{message}"):
        load_lens(path)


def test_a_photo_of_another_size_than_calibrated_is_refused():
    photo = np.zeros((720, 1280, 3), np.uint8)
    m = Pipeline(replace(Pipeline().params, lens=LENS)).measure(
        photo, grown_by_oracle('control', 'hard', 3, 1).cfg, None, Target(0.4 + 0.6j))
    assert not m.ok and m.error.code == BAD_INPUT
    assert 'the photo is 1280 x 720 px, the lens calibration is for 1920 x 1080 px' \
        in str(m.error)
    LENS.check((1080, 1920, 3))  # rows, columns: as calibrated
    with pytest.raises(CameraError, match='the photo is 1080 x 1920 px'):
        LENS.check((1920, 1080, 3))


def test_a_barrel_lens_is_measured_as_a_distortion_free_one_with_its_calibration():
    grown = grown_by_oracle('control', 'hard', seed=11, steps=24)
    c = grown.sim.chamber
    lens_only = Variation.only('lens')
    rig_seed = next(s for s in range(100)  # a strong barrel (k1 <= -0.045)
                    if draw_rig(s, lens_only, 1).distortion_k1 <= -0.045)
    shot = PhotoTwin(MarkerLayout()).photo(c, seed=4, variation=lens_only, rig_seed=rig_seed)
    calibrated = optics.calibration(draw_rig(rig_seed, lens_only, 1).distortion_k1,
                                    shot.bgr.shape[1::-1])
    tips = np.concatenate(c.tip_positions())
    measured, tip_error_m = {}, {}
    for name, lens in (('as is', None), ('calibrated', calibrated)):
        m = Pipeline(replace(Pipeline().params, lens=lens)).measure(
            shot.bgr, grown.cfg, c.light.copy(), Target(c.target), c.steps)
        assert m.ok, m.error
        measured[name] = m
        seen = m.tree.nodes[m.tree.tips]
        tip_error_m[name] = np.hypot(tips[:, None, 0] - seen[None, :, 0],
                                     tips[:, None, 1] - seen[None, :, 1]).min(axis=1)
    # The markers sit at the photo's edges, where the lens bends most: with its calibration
    # they fit the layout to a fraction of a millimetre, and the plant's tips land where the
    # simulator's are (as is: 3.3 mm off on average, one 6.7 mm).
    assert measured['calibrated'].fit.check_error_m < 1e-3
    assert measured['calibrated'].fit.check_error_m < 0.5 * measured['as is'].fit.check_error_m
    assert tip_error_m['calibrated'].max() < 3e-3
    assert tip_error_m['calibrated'].mean() < 0.6 * tip_error_m['as is'].mean()


def test_growspace_camera_measure_takes_the_calibration(tmp_path, capsys):
    from growspace_camera.cli import main
    grown = grown_by_oracle('control', 'hard', seed=11, steps=12)
    lens_only = Variation.only('lens')
    shot = PhotoTwin(MarkerLayout()).photo(grown.sim.chamber, seed=4, variation=lens_only,
                                           rig_seed=0)
    (tmp_path / 'rig.jpg').write_bytes(shot.jpeg)
    lens = optics.calibration(draw_rig(0, lens_only, 1).distortion_k1, shot.bgr.shape[1::-1])
    path = calibration_yaml(tmp_path / 'rig.yaml', camera_matrix={
        'rows': 3, 'cols': 3, 'data': lens.camera_matrix.reshape(-1).tolist()},
        distortion_coefficients={'rows': 1, 'cols': 5, 'data': lens.distortion.tolist()})
    assert main(['measure', str(tmp_path / 'rig.jpg'), '--lens', path]) == 0
    assert 'rig.jpg: reward' in capsys.readouterr().out
    small = tmp_path / 'small.jpg'  # another size than calibrated: named, not measured
    small.write_bytes(PhotoTwin(MarkerLayout(), size=(640, 360)).photo(grown.sim.chamber,
                                                                       seed=4).jpeg)
    assert main(['measure', str(small), '--lens', path]) == 1
    assert 'the lens calibration is for 1920 x 1080 px' in capsys.readouterr().out
