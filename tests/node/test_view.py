"""The view without ROS: markers and view image of known plants, bad input, the README's
pictures, and ``growspace-replay export --view``.

Frames are built with ``Scene`` from the messages a chamber publishes, made in process
(``view.sample``); tests/node/test_view_ros.py runs the node itself.
"""

from __future__ import annotations

import json
import math
import os
from typing import Any

import numpy as np
import pytest

from growspace_sim.core.config import SimConfig
from growspace_sim.ros import convert
from growspace_sim.ros import types
from growspace_sim.simulation import Simulation
from growspace_sim.view import markers, Scene, ViewInputError
from growspace_sim.view.image import PLANT_COLOURS, ViewRenderer
from growspace_sim.view.sample import episode_messages, feed

W = H = 0.84
TWIG = 0.015 * W  # branch_thickness x chamber width [m]

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


# ----------------------------------------------------------------------------- helpers
def plant_state(x: list[float], z: list[float], parent: list[int], plant: list[int] | None = None,
                stamp_ns: int = 1_000, step: int = 0) -> Any:
    n = len(x)
    return types.new(types.PLANT_STATE, header=convert.header(stamp_ns, 'chamber'), step=step,
                     node_x=x, node_z=z, parent=parent, plant=plant or [0] * n, tips=[],
                     branch_count=[])


def light_state(x: float, width: float = 0.2, stamp_ns: int = 1_000, spot: bool = False,
                z: float = 0.0, radius: float = 0.0) -> Any:
    return types.new(types.LIGHT_COMMAND, header=convert.header(stamp_ns, 'chamber'),
                     mode=convert.MODE_SPOT if spot else convert.MODE_BEAM, x=x, z=z,
                     width=width, radius=radius)


def result(step: int = 0, stamp_ns: int = 1_000, reward: float = 0.5) -> Any:
    return types.new(types.STEP_RESULT, header=convert.header(stamp_ns, 'chamber'), step=step,
                     reward=reward, plant_rewards=[reward])


def stem_frame(step: int = 0) -> Any:
    """A frame of one straight stem at x = 0.21 m: root, 0.168 m, 0.252 m (no config)."""
    scene = Scene()
    scene.on_plant(plant_state([0.21, 0.21, 0.21], [0.0, 0.168, 0.252], [-1, 0, 1], step=step))
    scene.on_light(light_state(0.3, 0.2))
    return scene.on_result(result(step))


def frames(cfg: SimConfig, seed: int, steps: int | None = None, scene: Scene | None = None,
           **kwargs: Any) -> list[Any]:
    scene = scene or Scene()
    out = []
    for topic, msg in episode_messages(cfg, seed, steps, **kwargs):
        frame = feed(scene, topic, msg)
        if frame is not None:
            out.append(frame)
    return out


def by_key(array: Any) -> dict[tuple[str, int], Any]:
    return {(m.ns, m.id): m for m in array.markers if m.action != markers.DELETEALL}


# ----------------------------------------------------------------------------- markers
def test_markers_of_a_known_stem_in_metres() -> None:
    array = markers.marker_array(stem_frame())
    ms = array.markers
    assert ms[0].action == markers.DELETEALL and ms[0].header.frame_id == 'chamber'
    assert [(m.ns, m.id) for m in ms[1:]] == list(markers.FIXED_IDS) + [('plant', 0)]
    found = by_key(array)
    walls = found['chamber', 0]
    assert walls.type == markers.LINE_STRIP
    assert [(p.x, p.y, p.z) for p in walls.points] == [
        (0, 0, 0), (W, 0, 0), (W, 0, H), (0, 0, H), (0, 0, 0)]
    beam = found['light', 0]
    assert beam.type == markers.CUBE and beam.color.a < 1.0  # translucent
    assert (beam.pose.position.x, beam.pose.position.y, beam.pose.position.z) == (0.3, 0, H / 2)
    assert (beam.scale.x, beam.scale.z) == (0.2, H)
    # No config: target and photons unknown, sent as DELETEs of their ids.
    assert found['target', 0].action == markers.DELETE
    assert found['photons', 0].action == found['photons', 1].action == markers.DELETE
    plant = found['plant', 0]
    assert plant.type == markers.TRIANGLE_LIST and len(plant.points) == 2 * 12
    pts = np.array([(p.x, p.y, p.z) for p in plant.points])
    # Segment 0 -> 1 has one node above it: thickness = twig x cbrt(2); 1 -> 2 is a twig.
    first, second = pts[:12], pts[12:]
    assert np.allclose(sorted(set(np.round(first[:6, 0], 9))),
                       [0.21 - TWIG * 2 ** (1 / 3) / 2, 0.21 + TWIG * 2 ** (1 / 3) / 2])
    assert np.allclose(first[:6, 1], 0.0) and set(np.round(first[:, 2], 9)) == {0.0, 0.168}
    assert np.allclose(sorted(set(np.round(second[6:, 1], 9))), [-TWIG / 2, TWIG / 2])
    assert set(np.round(second[:, 2], 9)) == {0.168, 0.252}
    # Every marker survives our codec (what goes on the wire; colours are float32 there).
    cdr = types.serialize(array, markers.MARKER_ARRAY)
    back = types.deserialize(cdr, markers.MARKER_ARRAY)
    assert types.serialize(back, markers.MARKER_ARRAY) == cdr
    assert [(m.ns, m.id, len(m.points)) for m in back.markers] == [
        (m.ns, m.id, len(m.points)) for m in ms]


def test_a_bare_root_is_deleted_not_sent_as_an_empty_triangle_list() -> None:
    scene = Scene()
    scene.on_plant(plant_state([0.2, 0.6, 0.6], [0.0, 0.0, 0.1], [-1, -1, 1], plant=[0, 1, 1]))
    found = by_key(markers.marker_array(scene.on_result(result(2))))
    assert found['plant', 0].action == markers.DELETE  # RViz flags a list without points
    assert found['plant', 1].action == markers.ADD and len(found['plant', 1].points) == 12
    assert (found['plant', 1].scale.x, found['plant', 1].scale.y) == (1.0, 1.0)  # RViz scales


def test_spotlight_is_a_disc_facing_the_viewer() -> None:
    scene = Scene()
    scene.on_plant(plant_state([0.42, 0.42], [0.0, 0.1], [-1, 0]))
    scene.on_light(light_state(0.5, spot=True, z=0.6, radius=0.08))
    spot = by_key(markers.marker_array(scene.on_result(result(3))))['light', 0]
    assert spot.type == markers.CYLINDER
    assert (spot.pose.position.x, spot.pose.position.z) == (0.5, 0.6)
    assert math.isclose(spot.scale.x, 0.16) and spot.scale.z == markers.SPOT_DEPTH
    q = spot.pose.orientation  # turns the cylinder's axis (z) onto y
    assert math.isclose(q.x, -math.sqrt(0.5)) and math.isclose(q.w, math.sqrt(0.5))


def test_exactly_one_deleteall_per_reset() -> None:
    scene = Scene()
    arrays = [markers.marker_array(f) for seed in (1, 2, 3)
              for f in frames(SimConfig(), seed, 6, scene=scene)]
    assert len(arrays) == 3 * 7
    deletes = [[m.action for m in a.markers].count(markers.DELETEALL) for a in arrays]
    assert deletes == ([1] + [0] * 6) * 3
    assert all(a.markers[0].action == markers.DELETEALL for a in arrays[::7])
    ids = {tuple((m.ns, m.id) for m in a.markers if m.action != markers.DELETEALL)
           for a in arrays}
    assert ids == {tuple(markers.FIXED_IDS) + (('plant', 0),)}  # stable ids every frame


def test_target_and_photons_follow_the_episode_from_config_and_seed() -> None:
    cfg, seed = SimConfig(challenge='control', setting='hard'), 7
    sim = Simulation(cfg)
    sim.reset(seed=seed)
    scene = Scene()
    got = frames(cfg, seed, scene=scene, oracle=False)
    assert len(got) == cfg.episode_length + 1 and scene.synced, scene.note
    target = by_key(markers.marker_array(got[0]))['target', 0]
    assert target.type == markers.SPHERE
    assert (target.pose.position.x, target.pose.position.z) == (sim.chamber.target.real,
                                                                sim.chamber.target.imag)
    assert math.isclose(target.scale.x, 2 * cfg.width_m(cfg.target_radius))
    for step, frame in enumerate(got):  # the same photons as an independent simulation
        if step:
            sim.step()
        assert np.array_equal(frame.photons, sim.chamber.photons)
        found = by_key(markers.marker_array(frame))
        lit, dark = found['photons', 0], found['photons', 1]
        assert len(lit.points) + len(dark.points) == sim.chamber.photons.size
        assert len(lit.points) == int(frame.lit.sum())
        assert all(p.y == 0.0 for p in dark.points[:5])


def test_shape_target_is_its_digit_pixels() -> None:
    cfg = SimConfig(challenge='shape')
    frame = frames(cfg, 3, 0)[0]
    target = by_key(markers.marker_array(frame))['target', 0]
    assert target.type == markers.CUBE_LIST
    assert len(target.points) == int(frame.target_mask.sum()) > 0
    pixel = W / frame.target_mask.shape[0]
    assert math.isclose(target.scale.x, pixel)
    rows, cols = np.nonzero(frame.target_mask)
    assert math.isclose(target.points[0].x, (cols[0] + 0.5) * pixel)
    assert math.isclose(target.points[0].z, H - (rows[0] + 0.5) * pixel)


def test_gantry_or_unfollowed_episodes_show_no_photons_but_the_target() -> None:
    cfg = SimConfig()
    msgs = list(episode_messages(cfg, 5, 2))
    payload = json.loads(msgs[0][1].data)
    payload['source'] = 'gantry'
    scene = Scene()
    scene.on_config(json.dumps(payload))
    last = [feed(scene, t, m) for t, m in msgs[1:]][-1]
    assert last.photons is None and last.target is not None
    # A plant that is not the re-simulated one: photons hidden from then on, target kept.
    scene = Scene()
    feed(scene, *msgs[0])
    scene.on_plant(plant_state([0.1, 0.1], [0.0, 0.2], [-1, 0], stamp_ns=77))
    frame = scene.on_result(result(0, stamp_ns=77))
    assert frame.photons is None and frame.target is not None and not scene.synced
    assert 'differs' in scene.note


@pytest.mark.parametrize('make, match', [
    (lambda: plant_state([0.1, 0.1], [0.0, 0.2], [-1, 5]), r'parent\[1\] = 5'),
    (lambda: plant_state([0.1, math.nan], [0.0, 0.2], [-1, 0]), r'node_x = nan'),
    (lambda: plant_state([0.1], [0.0, 0.2], [-1]), r'len\(node_z\) = 2'),
    (lambda: light_state(math.inf), r'light/state: x = inf'),
])
def test_bad_messages_are_refused_naming_field_and_value(make: Any, match: str) -> None:
    scene = Scene()
    msg = make()
    handler = scene.on_light if msg.__msgtype__ == types.LIGHT_COMMAND else scene.on_plant
    with pytest.raises(ViewInputError, match=match):
        handler(msg)
    with pytest.raises(ViewInputError, match='chamber/config: data'):
        scene.on_config('{not json')
    with pytest.raises(ViewInputError, match='chamber/config: config'):
        scene.on_config(json.dumps({'config': {'light_width': -1.0}}))


# ----------------------------------------------------------------------------- image
def test_view_image_size_and_plant_pixels_where_the_plant_is() -> None:
    frame = stem_frame(step=4)
    image = ViewRenderer(512).render(frame)
    assert image.shape == (512, 512, 3) and image.dtype == np.uint8
    assert ViewRenderer(200).render(frame).shape == (200, 200, 3)
    px = 512 / W
    col = round(0.21 * px)
    green = tuple(reversed(PLANT_COLOURS[0]))  # drawn BGR, published RGB
    for z in (0.03, 0.1, 0.2, 0.24):  # along the stem
        assert tuple(image[round((H - z) * px), col]) == green, z
    for z in (0.3, 0.6):  # above its top
        assert tuple(image[round((H - z) * px), col]) != green
    assert not (image[:, round(0.7 * px)] == green).all(axis=1).any()  # far from it
    # Anti-aliased: the stem's edge has blended pixels, neither plant nor background.
    row = image[round((H - 0.1) * px)]
    edge = {tuple(v) for v in row[col - 12:col + 12]} - {green, tuple(row[col - 12])}
    assert edge
    assert np.array_equal(ViewRenderer(512).render(frame), image)  # same frame, same bytes


def test_view_renderer_refuses_a_bad_size() -> None:
    with pytest.raises(ValueError, match='view_size must be an int in'):
        ViewRenderer(8)


# ----------------------------------------------------------------------------- README pictures
def test_readme_pictures_show_what_the_view_sends() -> None:
    """docs/view_markers.png and docs/view_image.png are what scripts/make_view_screenshot.py
    draws now, from the MarkerArray and the view image of the same frame."""
    import cv2

    from growspace_sim.view import marker_png
    from growspace_sim.view.sample import readme_frame

    docs = os.path.join(ROOT, 'docs')
    frame = readme_frame(Scene())
    array = markers.marker_array(frame)
    for name, now in (('view_markers.png', marker_png.draw(array, 512)),
                      ('view_image.png', ViewRenderer(512).render(frame))):
        path = os.path.join(docs, name)
        assert os.path.getsize(path) < 100_000, path
        shipped = cv2.cvtColor(cv2.imread(path), cv2.COLOR_BGR2RGB)
        assert shipped.shape == now.shape, name
        assert np.abs(shipped.astype(int) - now).mean() < 0.5, name
    # The markers picture has the plant's colour where the plant's nodes are.
    drawn = marker_png.draw(array, 512)
    green = tuple(round(255 * c) for c in markers.PLANT_COLOURS[0][:3])
    scale = 512 / (W * 1.1)
    hits = [tuple(drawn[round((H + 0.15 * W - z) * scale), round((x + 0.05 * W) * scale)])
            == green for x, z in zip(frame.node_x[1:], frame.node_z[1:])]
    assert np.mean(hits) > 0.8, hits


# ----------------------------------------------------------------------------- export --view
@pytest.mark.slow
def test_export_view_adds_markers_and_images_to_a_copy(tmp_path: Any) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from growspace_sim.replay.bag import Bag
    from growspace_sim.replay.cli import main as replay_main
    from growspace_sim.replay.resim import resimulate

    bag = os.path.join(ROOT, 'bags',
                       'oracle_shape_easy.mcap')
    out = tmp_path / 'view.mcap'
    assert replay_main(['export', bag, str(out), '--view', '--view-size', '256']) == 0
    assert replay_main(['export', bag, str(out), '--view']) == 2  # never overwritten
    with Bag(bag) as original, Bag(out) as copy:
        assert set(copy.topics) == set(original.topics) | {
            '/growspace/plant/markers', '/growspace/camera/image_view'}
        assert copy.metadata == original.metadata
        kept = [(m.topic, m.data, m.log_time) for m in copy.messages(original.topics)]
        assert kept == [(m.topic, m.data, m.log_time) for m in original.messages()]
        arrays = [m.decode() for m in copy.messages(['/growspace/plant/markers'])]
        results = [m.decode() for m in copy.messages(['/growspace/step_result'])]
        images = [m.decode() for m in copy.messages(['/growspace/camera/image_view'])]
    assert len(arrays) == len(results) == len(images) == 51
    assert [a.markers[0].header.stamp for a in arrays] == [r.header.stamp for r in results]
    assert arrays[0].markers[0].action == markers.DELETEALL
    assert all({k.ns: k.action for k in a.markers}['photons'] == markers.ADD for a in arrays)
    assert {k.ns: k.type for k in arrays[0].markers}['target'] == markers.CUBE_LIST  # digit
    assert (images[0].width, images[0].height, images[0].encoding) == (256, 256, 'rgb8')
    assert resimulate(out).ok  # the recording itself is untouched
    # A decoder that is not ours reads the added channels from their ros2msg schemas.
    with open(out, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = [msg for _, _, _, msg in reader.iter_decoded_messages(
            topics=['/growspace/plant/markers'])]
    assert len(decoded) == 51 and decoded[-1].markers[-1].ns == 'plant'


# ----------------------------------------------------------------------------- ViewNode in process
def test_view_node_draws_only_what_someone_reads() -> None:
    from growspace_sim.node.fake import FakeTransport
    from growspace_sim.node.view_node import IMAGE_TOPIC, MARKERS_TOPIC, ViewNode

    transport = FakeTransport('growspace_view', '/growspace')
    view = ViewNode(transport, view_size=128)
    transport.unread = {transport.resolve(MARKERS_TOPIC), transport.resolve(IMAGE_TOPIC)}
    messages = list(episode_messages(SimConfig(), 2, 6))
    for topic, msg in messages[:4]:  # config and the reset's tick: nobody reads
        transport.inject(topic, msg)
    assert view.frames == 0 and not transport.published
    transport.unread.discard(transport.resolve(MARKERS_TOPIC))  # RViz subscribes
    for topic, msg in messages[4:]:
        transport.inject(topic, msg)
    arrays = transport.messages(MARKERS_TOPIC)
    assert view.frames == len(arrays) == 6 and not transport.messages(IMAGE_TOPIC)
    assert all({k.ns: k.action for k in a.markers}['photons'] == markers.ADD for a in arrays)
    transport.unread.clear()
    transport.inject('plant/state', plant_state([0.1, 0.1], [0.0, 0.2], [-1, 3]))
    assert transport.warnings == [
        'plant/state: parent[1] = 3, expected -1 or an index below 1; message ignored.']
    transport.inject(*messages[-1])  # a step_result: drawn with the last good plant
    image = transport.messages(IMAGE_TOPIC)[-1]
    assert (image.width, image.height, image.header.frame_id) == (128, 128, 'chamber_camera')
    assert transport.qos[transport.resolve(MARKERS_TOPIC)].reliability == 'reliable'
