"""The rig end to end over real rclpy, without hardware: an agent steps ``GrowSpaceROS`` (the
Gymnasium bridge) on ``gantry_node`` (lockstep, a GRBL emulator on a pseudo-terminal, the photo
light on its flood output) and ``camera_node`` (photo twin: a simulated plant grown under the
light the gantry reached). The gantry's recording is read back and compared with what the agent
got. Then what a step is answered when the camera refuses a photo or is not running.
``./run.sh test`` runs this in a loopback-only network namespace.
"""

from __future__ import annotations

import json
import signal
import time

import cv2
import numpy as np
import pytest

from grbl_emulator import GrblEmulator
from growspace_camera import recorded as recorded_steps
from growspace_camera.resegment import resegment
from growspace_camera.settings import CameraParams, load_layout
from growspace_camera.twin import PhotoTwin
from growspace_gym_bridge.envs import GrowSpaceBridgeEnv
from growspace_gym_bridge.link import ChamberLink
from growspace_sim.core.config import SimConfig
from growspace_sim.envs.env import GrowSpaceEnv
from growspace_sim.node.rclpy_transport import RclpyTransport
from growspace_sim.replay.bag import Bag
from growspace_sim.ros import convert, types
from growspace_sim.simulation import Simulation
from ros_helpers import NodeProcess, wait_until_idle
from test_camera_ros import camera_executable
from test_gantry_node import RIG
from test_gantry_ros import gantry_executable

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

NAMESPACE = '/gs_test'
STEPS_OF_A_STEP = ('camera/image_raw', 'plant/state', 'light/state', 'camera/photo',
                   'camera/measurement', 'step_result')
ACTIONS = (1, 0, 2)
GROWTH_S = 0.3


@pytest.fixture
def grbl(tmp_path):
    emulator = GrblEmulator(RIG, speedup=100.0, link_dir=tmp_path).start()
    yield emulator
    emulator.stop()


def start_gantry(grbl: GrblEmulator, bag, *args: str) -> NodeProcess:
    return NodeProcess('-p', f'port:={grbl.port}', '-p', 'seed:=3', '-p', f'record_path:={bag}',
                       '-p', 'camera:=camera/capture', '-p', 'photo_light:=true',
                       '-p', 'photo_settle_s:=0.05', *args, namespace=NAMESPACE,
                       executable=gantry_executable())


def start_camera(source: str = 'twin') -> NodeProcess:
    return NodeProcess('-p', f'source:={source}', '-p', 'twin_seed:=2', namespace=NAMESPACE,
                       executable=camera_executable())


def recorded(bag) -> list[tuple[str, object]]:
    """(topic without the namespace, message) of the recording, in its order."""
    with Bag(bag) as b:
        return [(m.topic.removeprefix(NAMESPACE + '/'), types.deserialize(m.data, m.typename))
                for m in b.messages()]


def test_an_agent_steps_the_rig_and_the_recording_holds_each_steps_photo(grbl, tmp_path,
                                                                        monkeypatch):
    bag = tmp_path / 'rig.mcap'
    camera = start_camera()
    gantry = start_gantry(grbl, bag, '-p', 'capture_timeout_s:=30.0',  # a loaded CI machine
                          '-p', f'growth_s:={GROWTH_S}')
    env = None
    try:
        wait_until_idle(NAMESPACE)
        env = GrowSpaceBridgeEnv('control', 'easy', namespace=NAMESPACE, start_node=False,
                                 timeout_s=60.0, connect_timeout_s=30.0)
        obs, info = env.reset(seed=5)
        seen = [(obs, None, info)]
        step_s = []
        for action in ACTIONS:
            began = time.monotonic()
            obs, reward, terminated, truncated, info = env.step(action)
            step_s.append(time.monotonic() - began)
            seen.append((obs, reward, info))
    finally:
        if env is not None:
            env.close()
        gantry_code, gantry_log = gantry.stop(signal.SIGTERM)
        camera_code, camera_log = camera.stop(signal.SIGTERM)
    assert (gantry_code, camera_code) == (0, 0), gantry_log + camera_log
    assert 'Traceback' not in gantry_log + camera_log
    assert min(step_s) >= GROWTH_S, step_s  # each step grew under its light before its photo

    # The plant the twin grew is the simulator's under the reached light: the measured
    # reward is close to the simulator's own for the same seed and actions.
    local = GrowSpaceEnv('control', 'easy')
    local.reset(seed=5)
    for (_, reward, _), action in zip(seen[1:], ACTIONS):
        expected = local.step(action)[1]
        assert reward != 0.0 and abs(reward - expected) < 0.05, (reward, expected)

    # The recording: every answered step holds its image, plant, light, photo and measurement
    # with the step_result's stamp, in the simulator's order, and they are what the agent got.
    messages = recorded(bag)
    results = [msg for topic, msg in messages if topic == 'step_result']
    assert [r.step_id for r in results] == [0, 1, 2, 3] and not any(r.info for r in results)
    # Each step's growth period is in the record: the rule in the metadata, and the status
    # that says 'growing' once per step (a reset has none).
    with Bag(bag) as b:
        assert b.metadata['growspace_gantry']['growth_s'] == str(GROWTH_S)
    phases = [v.value for topic, msg in messages if topic == 'gantry/status'
              for v in msg.status[0].values if v.key == 'step']
    assert [p for i, p in enumerate(phases) if p == 'growing' and phases[i - 1] != p] == \
        ['growing'] * len(ACTIONS), phases
    for result, (obs, reward, info) in zip(results, seen):
        stamp = convert.to_ns(result.header.stamp)
        step = [(topic, msg) for topic, msg in messages if topic in STEPS_OF_A_STEP
                and convert.to_ns(msg.header.stamp) == stamp]
        assert [topic for topic, _ in step] == list(STEPS_OF_A_STEP), step
        image, plant, light, jpeg, measurement, _ = (msg for _, msg in step)
        assert np.array_equal(convert.image_from_msg(image), obs)
        assert measurement.ok and measurement.step_id == result.step_id
        assert result.reward == measurement.reward
        if reward is not None:
            assert reward == measurement.reward
        assert light.step_id == result.step_id and info['light']['x'] == light.x
        assert len(plant.tips) == len(info['tips'][0]) >= 1
        assert jpeg.format == 'jpeg'
        photo = cv2.imdecode(np.asarray(jpeg.data, np.uint8), cv2.IMREAD_COLOR)
        assert photo is not None and photo.shape == (1080, 1920, 3)
    # The photo light: on (M8) for each of the 4 photos, off (M9) after each, off at the end.
    assert grbl.lines.count('M8') == 4 and not grbl.coolant
    assert grbl.coolant_history[-8:] == [True, False] * 4

    # Re-segmented with the settings it ran with (camera_node's defaults), the recording gives
    # the camera's numbers again, each episode's target read from the gantry's chamber/config
    # (never laid out again: that path is for recordings made before it held the target).
    configs = [json.loads(msg.data) for topic, msg in messages if topic == 'chamber/config']
    assert len(configs) == 2 and configs[0]['reset_id'] == 0  # start-up, then the agent's
    assert all('target' in c for c in configs)

    def no_layout(*args):
        raise AssertionError('laid out again')
    monkeypatch.setattr(recorded_steps._Episodes, '_lay_out', no_layout)
    report = resegment(bag, tmp_path / 'again.mcap', CameraParams())
    assert (report.photos, report.measured, report.was_measured, report.changed) == (4, 4, 4, 0)


def test_a_refused_photo_and_a_missing_camera_answer_the_step_with_an_error(grbl, tmp_path):
    """No camera_node: the reset's answer says 'unavailable' once capture_timeout_s is over.
    Then a camera whose photo shows no marker: the answer names the camera's refusal; neither
    carries an image or a reward, and the recording keeps the refused photo."""
    bag = tmp_path / 'rig.mcap'
    photos = tmp_path / 'photos'
    photos.mkdir()
    sim = Simulation(SimConfig())
    sim.reset(seed=4)
    (photos / 'hidden.jpg').write_bytes(PhotoTwin(load_layout(), size=(640, 360)).photo(
        sim.chamber, 1, hidden=(0, 1, 2, 3)).jpeg)
    gantry = start_gantry(grbl, bag, '-p', 'capture_timeout_s:=5.0')
    camera = None
    transport = RclpyTransport('rig_test_client', NAMESPACE)
    try:
        wait_until_idle(NAMESPACE)
        link = ChamberLink(transport, with_state=True, with_image=True)
        assert link.connect(30.0)['source'] == 'gantry'
        reply = link.reset(1, seed=5, challenge='control', setting='easy', timeout_s=30.0)
        assert reply.result.info.startswith(
            f'error: camera: unavailable: no {NAMESPACE}/camera/capture service within '
            f'capture_timeout_s = 5 s'), reply.result.info
        assert reply.result.reward == 0.0 and reply.image is None
        camera = start_camera(str(photos))
        reply = link.reset(2, seed=5, challenge='control', setting='easy', timeout_s=30.0)
        while 'unavailable' in reply.result.info:  # camera_node still starting: try again
            reply = link.reset(reply.result.reset_id + 1, seed=5, challenge='control',
                               setting='easy', timeout_s=30.0)
        assert reply.result.info.startswith('error: camera: markers: '), \
            reply.result.info + camera.output() + gantry.output()
        assert reply.result.reward == 0.0 and list(reply.result.plant_rewards) == [0.0]
    finally:
        transport.close()
        gantry.stop(signal.SIGTERM)
        if camera is not None:
            camera.stop(signal.SIGTERM)
    messages = recorded(bag)
    assert not [msg for topic, msg in messages if topic == 'camera/image_raw']
    refused = [msg for topic, msg in messages if topic == 'camera/measurement']
    assert refused and not any(m.ok for m in refused) and refused[-1].error_code == 'markers'
    photos_kept = [msg for topic, msg in messages if topic == 'camera/photo']
    assert photos_kept and bytes(photos_kept[-1].data) == (photos / 'hidden.jpg').read_bytes()
    assert not grbl.coolant


def test_every_capture_answer_rclpy_hands_the_gantry_decodes() -> None:
    """rmw_serialize sizes a message by Fast CDR's estimate, which ran 8 or 16 bytes past a
    Capture_Response's data for about half of these: the gantry dropped such an answer as
    malformed until ``from_rclpy`` accepted the tail (the refused photo above never arrived)."""
    from growspace_msgs.srv import Capture
    from growspace_sim.node.rclpy_transport import from_rclpy

    rng = np.random.default_rng(0)
    for _ in range(200):
        reply = Capture.Response()
        reply.observation.encoding = 'x' * int(rng.integers(10))
        reply.observation.data = bytes(int(rng.integers(10)))
        reply.plant.node_x = [0.5] * int(rng.integers(4))
        reply.photo.format = 'jpeg'[:int(rng.integers(5))]
        reply.photo.data = bytes(int(rng.integers(10)))
        m = reply.measurement
        m.error, m.reward = 'e' * int(rng.integers(10)), float(rng.random())
        m.plant_rewards = [m.reward] * int(rng.integers(4))
        m.processing_s = 0.125
        got = from_rclpy(reply, 'growspace_msgs/srv/Capture_Response')
        assert (got.observation.encoding, bytes(got.photo.data), got.measurement.error,
                got.measurement.reward, list(got.measurement.plant_rewards),
                got.measurement.processing_s) == (
            reply.observation.encoding, bytes(reply.photo.data), m.error, m.reward,
            list(m.plant_rewards), 0.125)
