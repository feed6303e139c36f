"""The installed ``camera_node`` on real rclpy: a stand-in for the gantry calls camera/capture
with the generated service classes and gets the step's outputs back (the photo twin is the
camera: no device is opened). ``./run.sh test`` runs this in a loopback-only namespace.
"""

from __future__ import annotations

import json
import os
import signal

from ament_index_python.packages import get_package_prefix
import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

import pytest

from growspace_msgs.msg import LightCommand
from growspace_msgs.srv import Capture
from ros_helpers import NodeProcess, TIMEOUT_S

from growspace_sim.core.config import SimConfig
from growspace_sim.ros.interface import config_json
from growspace_sim.simulation import Simulation


# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

def camera_executable() -> str:
    return os.path.join(get_package_prefix('growspace_camera'), 'lib', 'growspace_camera',
                        'camera_node')


@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
def test_one_capture_request_is_answered_with_observation_plant_and_reward() -> None:
    node = NodeProcess('-p', 'source:=twin', '-p', 'twin_seed:=2',
                       executable=camera_executable())
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    executor = SingleThreadedExecutor(context=context)
    try:
        client_node = Node('gantry_stand_in', namespace='/gs_test', context=context)
        executor.add_node(client_node)
        client = client_node.create_client(Capture, 'camera/capture')
        assert client.wait_for_service(timeout_sec=TIMEOUT_S), node.output()
        sim = Simulation(SimConfig(challenge='find_plant', setting='hard'))
        outcome = sim.reset(seed=8)
        light = sim.chamber.light
        request = Capture.Request(
            step_id=0, step=0, config=config_json(sim.cfg, 8),
            light=LightCommand(mode=LightCommand.MODE_BEAM, x=light.x, width=light.width),
            has_point_target=True, target_x=sim.chamber.target.real,
            target_z=sim.chamber.target.imag)
        request.header.stamp.sec, request.header.stamp.nanosec = 1234, 5678
        future = client.call_async(request)
        executor.spin_until_future_complete(future, timeout_sec=TIMEOUT_S)
        assert future.done(), node.output()
        reply = future.result()
        m = reply.measurement
        assert m.ok, m.error
        assert abs(m.reward - outcome.reward) < 0.05
        assert list(m.markers_seen) == [0, 1, 2, 3] and m.processing_s > 0
        for msg in (reply.observation, reply.plant, reply.photo, m):
            assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1234, 5678)
        image = np.asarray(reply.observation.data, np.uint8).reshape(84, 84, 3)
        assert np.array_equal(image[..., 2], sim.observe()[..., 2])  # the light as reached
        assert np.count_nonzero(image[..., 1]) > 0 and len(reply.plant.tips) >= 1
        assert reply.photo.format == 'jpeg' and len(reply.photo.data) > 10_000
        bad = Capture.Request(config=json.dumps({'config': {'challenge': 'nope'}}))
        future = client.call_async(bad)
        executor.spin_until_future_complete(future, timeout_sec=TIMEOUT_S)
        assert future.result().measurement.error_code == 'bad_input'
        code, log = node.stop(signal.SIGTERM)
        assert code == 0, log
        assert 'Traceback' not in log
    finally:
        node.stop(signal.SIGKILL)
        executor.shutdown()
        context.try_shutdown()


def test_an_invalid_parameter_exits_2_naming_it() -> None:
    node = NodeProcess('-p', 'pixel_size_m:=0.5', executable=camera_executable())
    code, log = node.stop(signal.SIGCONT)  # let it end by itself
    assert code == 2, log
    assert 'camera_node: invalid parameter: pixel_size_m must be in [0.0005, 0.02], got 0.5' \
        in log
