"""``sim_node`` against real ROS 2 (rclpy + rmw_fastrtps_cpp): what a ROS user sees and gets.

Every client here is an rclpy node using the rosidl-generated classes (``growspace_msgs.msg``,
``sensor_msgs.msg.Image``, ``rcl_interfaces.srv``), never our own codec. One lockstep node is
shared by the module; the tests that need other command lines start their own. Run inside a
loopback-only network namespace (``unshare -n``), as ``./run.sh test`` does.
"""

from __future__ import annotations

from collections.abc import Iterator
import json
import os
import secrets
import signal
import subprocess
import sys
import tempfile
import time
from typing import Any

import gymnasium
import numpy as np
import pytest
import rclpy.qos

from growspace_msgs.msg import LightCommand, ResetRequest, StepResult
from growspace_msgs.srv import Reset
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import (DescribeParameters, GetParameters, ListParameters,
                                SetParameters)
from ros_helpers import TIMEOUT_S, Client, NodeProcess, sim_node_executable
from waiting import wait_until
from growspace_sim.core import task as tasks
import growspace_sim.envs.registration  # noqa: F401 - registers the GrowSpace ids

from growspace_sim.node import params
from growspace_sim.ros import interface
from growspace_sim.ros import types

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

NAMESPACE = f'/gs_node_{secrets.token_hex(3)}'
NODE = 'growspace_sim'
EPISODE = 10
SEED = 1


# ----------------------------------------------------------------------------- helpers
def call(client: Client, srv_type: Any, name: str, request: Any) -> Any:
    """Call a service from the client's node and wait for its answer."""
    cli = client.node.create_client(srv_type, name)
    try:
        assert client.spin_until(cli.service_is_ready), f'service {name} not available'
        future = cli.call_async(request)
        assert client.spin_until(future.done), f'no answer from {name}'
        return future.result()
    finally:
        client.node.destroy_client(cli)


def get_params(client: Client, names: list[str], node: str) -> list[ParameterValue]:
    return call(client, GetParameters, f'{node}/get_parameters',
                GetParameters.Request(names=names)).values


def set_param(client: Client, name: str, value: ParameterValue, node: str) -> Any:
    request = SetParameters.Request(parameters=[Parameter(name=name, value=value)])
    results = call(client, SetParameters, f'{node}/set_parameters', request).results
    assert len(results) == 1
    return results[0]


def python_value(value: ParameterValue) -> Any:
    """The Python value a ParameterValue carries."""
    by_type = {ParameterType.PARAMETER_BOOL: 'bool_value',
               ParameterType.PARAMETER_INTEGER: 'integer_value',
               ParameterType.PARAMETER_DOUBLE: 'double_value',
               ParameterType.PARAMETER_STRING: 'string_value',
               ParameterType.PARAMETER_INTEGER_ARRAY: 'integer_array_value'}
    field = by_type[value.type]
    out = getattr(value, field)
    return list(out) if field.endswith('array_value') else out


def wait_image(client: Client, result: StepResult) -> Any:
    """The camera image published with ``result`` (the same header stamp)."""
    stamp = (result.header.stamp.sec, result.header.stamp.nanosec)

    def find() -> Any:
        return next((m for m in client.images
                     if (m.header.stamp.sec, m.header.stamp.nanosec) == stamp), None)
    assert client.spin_until(lambda: find() is not None), f'no image stamped {stamp}'
    return find()


def reset_and_wait(client: Client, reset_id: int, seed: int, **fields: Any) -> StepResult:
    result = client.reset(reset_id, has_seed=True, seed=seed, **fields)
    assert result.info == '', result.info
    return result


def step(client: Client, reset_id: int, step_id: int, action: int) -> StepResult:
    """One lockstep step; waits for the StepResult of this episode (``Client.step`` may match
    a late result of an earlier episode with the same step_id)."""
    client.command.publish(LightCommand(step_id=step_id, mode=LightCommand.MODE_DISCRETE,
                                        action=action))
    return client.wait_result(lambda m: m.reset_id == reset_id and m.step_id == step_id)


@pytest.fixture(scope='module')
def node() -> Iterator[NodeProcess]:
    """One lockstep node for the module: short episodes, seed 1."""
    process = NodeProcess('-p', f'seed:={SEED}', '-p', f'episode_length:={EPISODE}',
                          namespace=NAMESPACE)
    try:
        yield process
    finally:
        code, output = process.stop()
        assert code == 0, output[-2000:]


@pytest.fixture(scope='module')
def client(node: NodeProcess) -> Iterator[Client]:
    c = Client(NAMESPACE)
    try:
        c.connect()
        yield c
    finally:
        c.close()


@pytest.fixture
def fresh(client: Client) -> Client:
    """The module client with its received messages cleared."""
    client.results.clear()
    client.images.clear()
    return client


# ----------------------------------------------------------------------------- 10. executable
def test_installed_executable_is_what_ros2_run_starts() -> None:
    exe = sim_node_executable()
    assert exe.endswith('install/growspace_sim/lib/growspace_sim/sim_node'), exe
    assert os.path.isfile(exe) and os.access(exe, os.X_OK), exe


# ----------------------------------------------------------------------------- 1. graph
def test_node_name_and_namespace(client: Client) -> None:
    # Node names travel apart from the endpoints (ROS's discovery info): matched topics do not
    # mean the graph already has the name (seen once on a loaded machine).
    client.wait_until(lambda: (NODE, NAMESPACE) in client.node.get_node_names_and_namespaces(),
                      60.0, f'the graph names the node {NAMESPACE}/{NODE}')


def test_topics_and_types(client: Client) -> None:
    found = dict(client.node.get_topic_names_and_types())
    for topic in interface.TOPICS:
        name = topic.name if topic.name.startswith('/') else f'{NAMESPACE}/{topic.name}'
        assert found.get(name) == [topic.typename], (name, found.get(name))


@pytest.mark.parametrize('topic', interface.OUTPUTS, ids=lambda t: t.key)
def test_publisher_qos_and_type_hash(client: Client, topic: interface.Topic) -> None:
    name = topic.name if topic.name.startswith('/') else f'{NAMESPACE}/{topic.name}'
    infos = [i for i in client.node.get_publishers_info_by_topic(name)
             if i.node_name == NODE and i.node_namespace == NAMESPACE]
    assert len(infos) == 1, infos
    info = infos[0]
    assert info.topic_type == topic.typename
    assert info.qos_profile.reliability.name.lower() == topic.qos.reliability
    assert info.qos_profile.durability.name.lower() == topic.qos.durability
    assert str(info.topic_type_hash) == types.type_hash(topic.typename)
    assert str(info.topic_type_hash).startswith('RIHS01_')


def test_config_is_latched(client: Client) -> None:
    infos = client.node.get_publishers_info_by_topic(f'{NAMESPACE}/chamber/config')
    assert [i.qos_profile.durability for i in infos if i.node_name == NODE] == [
        rclpy.qos.DurabilityPolicy.TRANSIENT_LOCAL]


@pytest.mark.parametrize('topic', interface.INPUTS, ids=lambda t: t.key)
def test_subscription_qos_and_type_hash(client: Client, topic: interface.Topic) -> None:
    infos = [i for i in client.node.get_subscriptions_info_by_topic(
        f'{NAMESPACE}/{topic.name}') if i.node_name == NODE]
    assert len(infos) == 1, infos
    assert infos[0].qos_profile.reliability.name.lower() == topic.qos.reliability
    assert str(infos[0].topic_type_hash) == types.type_hash(topic.typename)


# ----------------------------------------------------------------------------- 2. lockstep
def test_every_step_answered_exactly_once_across_resets(fresh: Client) -> None:
    extra = 2  # commands after the episode's end: answered 'episode over', not stepped
    window = 4  # commands in flight at once
    for episode in range(3):
        reset_id = 100 + episode
        reset_and_wait(fresh, reset_id, seed=episode)
        ids = list(range(1, EPISODE + extra + 1))
        for i in ids:
            fresh.command.publish(LightCommand(step_id=i, mode=LightCommand.MODE_DISCRETE,
                                               action=i % 3))
            if i > window:
                fresh.wait_result(lambda m, j=i - window, r=reset_id: m.reset_id == r
                                  and m.step_id == j)
        fresh.wait_result(lambda m, r=reset_id, last=ids[-1]: m.reset_id == r
                          and m.step_id == last)
        fresh.drain(0.2)  # a deliberate negative check: a duplicate answer would arrive now
        mine = [r for r in fresh.results if r.reset_id == reset_id and r.step_id > 0]
        counts = {i: sum(r.step_id == i for r in mine) for i in ids}
        assert counts == dict.fromkeys(ids, 1), counts
        by_id = {r.step_id: r for r in mine}
        assert [by_id[i].step for i in ids[:EPISODE]] == ids[:EPISODE]
        assert [by_id[i].truncated for i in ids] == [False] * (EPISODE - 1) + [True] * (
            extra + 1)
        assert all('episode over' in by_id[i].info for i in ids[EPISODE:])


def test_a_flood_of_commands_is_answered_without_loss(fresh: Client) -> None:
    """2,000 commands as fast as rclpy sends them: each gets exactly one StepResult (the
    command QoS is keep_all, so the sender waits instead of the node dropping commands)."""
    flood = 2_000
    answers: list[StepResult] = []
    fresh.node.create_subscription(StepResult, 'step_result', answers.append,
                                   rclpy.qos.QoSProfile(
                                       depth=1, history=rclpy.qos.HistoryPolicy.KEEP_ALL))
    # Sent with the node's own command QoS (keep_all): a keep_last writer would overwrite
    # commands the node has not acknowledged yet whenever it falls behind.
    sender = fresh.node.create_publisher(LightCommand, 'light/command', rclpy.qos.QoSProfile(
        depth=1, history=rclpy.qos.HistoryPolicy.KEEP_ALL))
    fresh.wait_until(lambda: sender.get_subscription_count() > 0, TIMEOUT_S,
                     'the node matches our new writer')
    fresh.reset_until(lambda rid: any(r.reset_id == rid for r in answers), 140,
                      'a reset answer reaches our new reader')
    reset_and_wait(fresh, 150, seed=3)
    for i in range(1, flood + 1):
        sender.publish(LightCommand(step_id=i, mode=LightCommand.MODE_DISCRETE, action=i % 5))
    fresh.wait_until(lambda: sum(r.reset_id == 150 and r.step_id > 0
                                 for r in answers) >= flood, 240.0,
                     f'answers to all {flood} commands')  # 60 s ran out beside two burners
    fresh.drain(0.2)  # a deliberate negative check: an extra answer would arrive now
    ids = sorted(r.step_id for r in answers if r.reset_id == 150 and r.step_id > 0)
    assert ids == list(range(1, flood + 1))
    fresh.node.destroy_publisher(sender)


def test_same_seed_gives_same_episode_other_seed_differs(fresh: Client) -> None:
    runs = []
    for reset_id, seed in ((200, 5), (201, 5), (202, 6)):
        first = reset_and_wait(fresh, reset_id, seed)
        images = [bytes(wait_image(fresh, first).data)]
        rewards = []
        for i in range(1, 4):
            result = step(fresh, reset_id, i, 1)
            rewards.append(result.reward)
            images.append(bytes(wait_image(fresh, result).data))
        runs.append((rewards, images))
    assert runs[0] == runs[1]
    assert runs[0] != runs[2]


@pytest.mark.parametrize('challenge', tasks.names())
def test_episode_over_ros_is_bit_identical_to_in_process(fresh: Client, challenge: str) -> None:
    env = gymnasium.make(growspace_sim.envs.registration.env_id(challenge, 'easy'),
                         episode_length=EPISODE)
    seed, reset_id = 11, 300 + tasks.names().index(challenge)
    try:
        obs, _ = env.reset(seed=seed)
        result = reset_and_wait(fresh, reset_id, seed, challenge=challenge, setting='easy')
        image = wait_image(fresh, result)
        assert (image.height, image.width) == obs.shape[:2]
        assert bytes(image.data) == obs.tobytes(), f'{challenge} reset image'
        env.action_space.seed(seed)
        for i in range(1, EPISODE + 1):
            action = env.action_space.sample()
            obs, reward, terminated, truncated, info = env.step(action)
            result = step(fresh, reset_id, i, int(action))
            assert result.info == '', result.info
            assert result.reward == reward, f'{challenge} step {i}: {result.reward} != {reward}'
            assert list(result.plant_rewards) == list(info['plant_rewards']), i
            assert (result.truncated, result.success, result.step) == (
                truncated, info['success'], info['step']), i
            assert bytes(wait_image(fresh, result).data) == obs.tobytes(), f'{challenge} {i}'
        assert truncated
    finally:
        env.close()
        reset_and_wait(fresh, 399, SEED, challenge='control', setting='easy')


# ----------------------------------------------------------------------------- 4. reset service
def test_reset_service_starts_an_episode(fresh: Client) -> None:
    response = call(fresh, Reset, 'reset', Reset.Request(has_seed=True, seed=3))
    assert response.success, response.message
    assert response.message == ''
    assert response.reset_id > 0
    result = fresh.wait_result(lambda m: m.reset_id == response.reset_id and m.step_id == 0)
    assert result.step == 0 and result.info == ''
    assert step(fresh, response.reset_id, 1, 0).step == 1


def test_reset_service_rejects_an_unknown_challenge(fresh: Client) -> None:
    response = call(fresh, Reset, 'reset', Reset.Request(challenge='bogus'))
    assert not response.success
    assert 'challenge' in response.message and 'bogus' in response.message, response.message
    assert response.reset_id == 0


# ----------------------------------------------------------------------------- 7. challenge param
def test_reset_switching_challenge_shows_in_parameters(fresh: Client) -> None:
    node = f'{NAMESPACE}/{NODE}'
    try:
        reset_and_wait(fresh, 500, 1, challenge='shape')
        assert get_params(fresh, ['challenge'], node)[0].string_value == 'shape'
        response = call(fresh, Reset, 'reset', Reset.Request(challenge='fairness',
                                                             setting='hard'))
        assert response.success, response.message
        values = get_params(fresh, ['challenge', 'setting'], node)
        assert [v.string_value for v in values] == ['fairness', 'hard']
    finally:
        reset_and_wait(fresh, 501, SEED, challenge='control', setting='easy')
    assert get_params(fresh, ['challenge', 'setting'], node)[0].string_value == 'control'


# ----------------------------------------------------------------------------- 5. parameters
def test_list_parameters_has_every_field_and_setting(client: Client) -> None:
    response = call(client, ListParameters, f'{NAMESPACE}/{NODE}/list_parameters',
                    ListParameters.Request())
    names = set(response.result.names)
    missing = {s.name for s in params.specs()} - names
    assert not missing, missing


def test_get_parameters_for_all_names_gives_every_value(client: Client) -> None:
    node = f'{NAMESPACE}/{NODE}'
    names = list(call(client, ListParameters, f'{node}/list_parameters',
                      ListParameters.Request()).result.names)
    values = get_params(client, names, node)
    assert len(values) == len(names), (len(values), len(names))
    unset = [n for n, v in zip(names, values) if v.type == ParameterType.PARAMETER_NOT_SET]
    assert not unset, unset
    got = {n: python_value(v) for n, v in zip(names, values) if n in params.defaults()}
    expected = params.defaults() | {'seed': SEED, 'episode_length': EPISODE}
    assert got == expected


def test_set_valid_parameter_is_accepted(client: Client) -> None:
    node = f'{NAMESPACE}/{NODE}'
    old = get_params(client, ['shape_success'], node)[0].double_value
    try:
        result = set_param(client, 'shape_success', ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=0.75), node)
        assert result.successful, result.reason
        assert get_params(client, ['shape_success'], node)[0].double_value == 0.75
    finally:
        assert set_param(client, 'shape_success', ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=old), node).successful


def test_set_invalid_parameter_is_rejected_naming_field_and_value(client: Client) -> None:
    node = f'{NAMESPACE}/{NODE}'
    result = set_param(client, 'light_density', ParameterValue(
        type=ParameterType.PARAMETER_INTEGER, integer_value=-5), node)
    assert not result.successful
    assert 'light_density' in result.reason and '-5' in result.reason, result.reason
    assert get_params(client, ['light_density'], node)[0].integer_value == 200


@pytest.mark.parametrize('name,value', [
    ('mode', ParameterValue(type=ParameterType.PARAMETER_STRING, string_value='realtime')),
    ('rate_hz', ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=99.0))])
def test_set_read_only_parameter_is_refused(client: Client, name: str,
                                            value: ParameterValue) -> None:
    node = f'{NAMESPACE}/{NODE}'
    before = get_params(client, [name], node)[0]
    result = set_param(client, name, value, node)
    assert not result.successful
    assert name in result.reason, result.reason
    assert get_params(client, [name], node)[0] == before


def test_describe_gives_ranges_constraints_and_when_changes_apply(client: Client) -> None:
    node = f'{NAMESPACE}/{NODE}'
    names = ['light_density', 'light_width', 'image_size', 'challenge', 'rate_hz', 'mode']
    found = call(client, DescribeParameters, f'{node}/describe_parameters',
                 DescribeParameters.Request(names=names)).descriptors
    d = {x.name: x for x in found}
    assert [(r.from_value, r.to_value, r.step) for r in d['light_density'].integer_range] \
        == [(1, 100_000, 1)]
    assert 'photons scattered per episode' in d['light_density'].description
    assert d['light_density'].description.endswith('Applies at the next reset.')
    assert not d['light_density'].read_only
    assert [(r.from_value, r.to_value) for r in d['light_width'].floating_point_range] \
        == [(0.0, 1.0)]
    assert d['light_width'].additional_constraints == \
        'greater than 0; light_width_min <= light_width <= light_width_max'
    assert [(r.from_value, r.to_value) for r in d['image_size'].integer_range] == [(0, 1024)]
    assert d['challenge'].additional_constraints == (
        'one of control, find_plant, fairness, shape; or module:attribute naming a Task of your '
        'own (loaded on first use)')
    assert d['mode'].read_only and d['rate_hz'].read_only  # this node runs in lockstep
    assert d['rate_hz'].description.endswith('Applies at once, in realtime mode (read-only in '
                                             'lockstep).')


def test_set_out_of_range_is_refused_by_the_standard_service(client: Client) -> None:
    node = f'{NAMESPACE}/{NODE}'
    result = set_param(client, 'light_width', ParameterValue(
        type=ParameterType.PARAMETER_DOUBLE, double_value=1.5), node)
    assert not result.successful and 'light_width' in result.reason and '1.5' in result.reason
    result = set_param(client, 'light_width', ParameterValue(  # in range, but 0 is not allowed
        type=ParameterType.PARAMETER_DOUBLE, double_value=0.0), node)
    assert not result.successful, result
    assert result.reason == 'light_width must be in ]0.0, 1.0], got 0.0.'
    assert get_params(client, ['light_width'], node)[0].double_value == 0.25


# ----------------------------------------------------------------------------- 3. realtime
def test_realtime_mode_steps_at_rate_hz() -> None:
    ns = f'{NAMESPACE}_rt'
    process = NodeProcess('-p', 'mode:=realtime', '-p', 'rate_hz:=50.0',
                          '-p', 'episode_length:=1000', namespace=ns)
    client = Client(ns)
    try:
        client.connect()
        assert client.spin_until(lambda: len(client.results) > 2)
        client.results.clear()
        start = time.monotonic()
        client.drain(2.0)
        elapsed = time.monotonic() - start
        steps = [r.step for r in client.results]
        # The node's rate: the steps it made meanwhile (a stalled reader may miss some).
        made = steps[-1] - steps[0] + 1
        assert 25 <= made / elapsed <= 70, (made, elapsed)  # loose: CI is loaded
        assert all(r.step_id == 0 for r in client.results)
        stamps = [r.header.stamp.sec * 10**9 + r.header.stamp.nanosec for r in client.results]
        # Sim time: 1/rate_hz per step. Results keep the last 10 for a slow reader, so a stall
        # of this client may skip some: the stamps must then skip as many steps' time.
        assert all(np.diff(steps) >= 1), steps
        assert list(np.diff(stamps)) == [20_000_000 * k for k in np.diff(steps)]
    finally:
        client.close()
        code, output = process.stop()
    assert code == 0, output[-2000:]


def test_realtime_rate_changes_live_and_the_timer_follows() -> None:
    ns = f'{NAMESPACE}_rate'
    process = NodeProcess('-p', 'mode:=realtime', '-p', 'rate_hz:=20.0',
                          '-p', 'episode_length:=1000', namespace=ns)
    client = Client(ns)
    node = f'{ns}/{NODE}'
    try:
        client.connect()
        assert client.spin_until(lambda: len(client.results) > 2)
        result = set_param(client, 'rate_hz', ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=80.0), node)
        assert result.successful, result.reason

        def at_new_rate() -> bool:  # the last two results are 1/80 s apart in sim time
            stamps = [r.header.stamp.sec * 10**9 + r.header.stamp.nanosec
                      for r in client.results[-2:]]
            return len(stamps) == 2 and stamps[1] - stamps[0] == 12_500_000
        client.wait_until(at_new_rate, TIMEOUT_S, 'steps at the new rate')
        client.results.clear()
        start = time.monotonic()
        client.drain(2.0)
        rate = len(client.results) / (time.monotonic() - start)
        # The old timer would give 20 Hz. A loaded 2-core CI machine delivered 44 of the 80 Hz,
        # so the lower bound only says "clearly faster than before"; the stamps below are exact.
        assert 30 <= rate <= 110, rate
        stamps = [r.header.stamp.sec * 10**9 + r.header.stamp.nanosec for r in client.results]
        steps = [r.step for r in client.results]
        # Sim time follows: 1/80 s per step. Results keep the last 10 for a slow reader (a
        # 225 ms stall of this client once lost 17 in a row), so steps are compared too.
        assert all(np.diff(steps) >= 1), steps
        assert list(np.diff(stamps)) == [12_500_000 * k for k in np.diff(steps)]
        result = set_param(client, 'rate_hz', ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=-1.0), node)
        assert not result.successful and 'rate_hz' in result.reason
        assert get_params(client, ['rate_hz'], node)[0].double_value == 80.0
    finally:
        client.close()
        code, output = process.stop()
    assert code == 0, output[-2000:]


# ----------------------------------------------------------------------------- 6. command line
@pytest.fixture(scope='module')
def remapped(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[NodeProcess, str]]:
    """A node started with a namespace, a node name, a topic remap, a params file and -p."""
    tmp = tmp_path_factory.mktemp('cli')
    params_file = tmp / 'params.yaml'
    params_file.write_text('/**:\n  ros__parameters:\n    light_density: 100\n')
    ns = f'/x_{secrets.token_hex(3)}'
    process = NodeProcess('-r', '__node:=other_name', '-r', 'step_result:=results',
                          '--params-file', str(params_file), '-p', 'episode_length:=7',
                          '-p', 'rate_hz:=20', '-p', 'bogus_param:=1', namespace=ns)
    try:
        yield process, ns
    finally:
        code, output = process.stop()
        assert code == 0, output[-2000:]


@pytest.fixture(scope='module')
def remapped_client(remapped: tuple[NodeProcess, str]) -> Iterator[Client]:
    _, ns = remapped
    c = Client(ns)
    results: list[StepResult] = []
    c.node.create_subscription(StepResult, 'results', results.append, 100)
    c.remapped_results = results  # type: ignore[attr-defined]
    try:
        assert c.spin_until(lambda: ('other_name', ns) in
                            c.node.get_node_names_and_namespaces()), 'node did not appear'
        assert c.spin_until(lambda: c.command.get_subscription_count() > 0
                            and c.node.count_publishers(f'{ns}/results') > 0)
        c.reset_until(lambda rid: any(r.reset_id == rid for r in results), 1000,
                      'a reset answer on the remapped topic')
        yield c
    finally:
        c.close()


def test_node_name_and_namespace_remaps(remapped: tuple[NodeProcess, str],
                                        remapped_client: Client) -> None:
    _, ns = remapped

    def named() -> list:
        graph = remapped_client.node.get_node_names_and_namespaces()
        return graph if ('other_name', ns) in graph else []

    graph = remapped_client.wait_until(named, 60.0, f'the graph names the node {ns}/other_name')
    assert (NODE, ns) not in graph


def test_topic_remap_moves_step_results(remapped: tuple[NodeProcess, str],
                                        remapped_client: Client) -> None:
    _, ns = remapped
    topics = dict(remapped_client.node.get_topic_names_and_types())
    assert topics.get(f'{ns}/results') == [types.STEP_RESULT]
    assert remapped_client.node.count_publishers(f'{ns}/step_result') == 0
    results = remapped_client.remapped_results  # type: ignore[attr-defined]
    remapped_client.reset_pub.publish(ResetRequest(reset_id=7, has_seed=True, seed=2))
    assert remapped_client.spin_until(lambda: any(r.reset_id == 7 for r in results))
    remapped_client.command.publish(LightCommand(step_id=1, mode=LightCommand.MODE_DISCRETE,
                                                 action=0))
    assert remapped_client.spin_until(lambda: any(r.step_id == 1 and r.reset_id == 7
                                                  for r in results))


def test_params_file_and_overrides_reach_the_node(remapped: tuple[NodeProcess, str],
                                                  remapped_client: Client) -> None:
    _, ns = remapped
    values = get_params(remapped_client, ['light_density', 'episode_length', 'rate_hz'],
                        f'{ns}/other_name')
    assert values[0].integer_value == 100  # from the params file
    assert values[1].integer_value == 7  # -p
    assert values[2].type == ParameterType.PARAMETER_DOUBLE  # -p rate_hz:=20 is a double
    assert values[2].double_value == 20.0


def test_unknown_parameter_is_warned_about_by_name(remapped: tuple[NodeProcess, str],
                                                   remapped_client: Client) -> None:
    process, _ = remapped
    assert process.proc.poll() is None, process.output()[-2000:]
    assert remapped_client.spin_until(lambda: 'bogus_param' in process.output(), 5.0), \
        process.output()[-2000:]


def test_invalid_parameter_exits_2_with_one_line() -> None:
    proc = subprocess.run([sim_node_executable(), '--ros-args', '-r', f'__ns:={NAMESPACE}_bad',
                           '-p', 'light_density:=-5'],
                          capture_output=True, text=True, timeout=TIMEOUT_S)
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert 'light_density' in lines[0] and '-5' in lines[0], lines[0]


def _executable(package: str, name: str) -> str:
    from ament_index_python.packages import get_package_prefix

    return os.path.join(get_package_prefix(package), 'lib', package, name)


def test_a_bad_ros_command_line_exits_2_with_one_line_for_every_node(tmp_path: Any) -> None:
    broken = tmp_path / 'broken.yaml'
    broken.write_text('/**:\n  ros__parameters: [1, 2\n')
    missing = tmp_path / 'missing.yaml'
    cases = {  # (executable, arguments): what the one line must name
        ('sim_node', '--params-file', str(missing)): str(missing),
        ('sim_node', '--params-file', str(broken)): str(broken),
        ('sim_node', '-p'): '-p',
        ('sim_node', '--no-such-flag'): '--no-such-flag',
        ('gantry_node', '--params-file', str(missing)): str(missing),
        ('view_node', '--params-file', str(broken)): str(broken),
    }
    where = {'sim_node': 'growspace_sim', 'view_node': 'growspace_sim',
             'gantry_node': 'growspace_gantry'}
    runs = {case: subprocess.Popen([_executable(where[case[0]], case[0]), '--ros-args',
                                    *case[1:]], stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True) for case in cases}
    for case, proc in runs.items():  # started together: each pays its imports at once
        out, err = proc.communicate(timeout=TIMEOUT_S)
        lines = err.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1, (case, proc.returncode, err)
        assert lines[0].startswith(f'{case[0]}: ') and cases[case] in lines[0], (case, err)
        assert 'Traceback' not in err and '/project/src' not in err, (case, err)


# ----------------------------------------------------------------------------- 8. recording
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_recording_is_finished_by_a_signal_and_resimulates(tmp_path: Any, sig: int) -> None:
    from growspace_sim.replay import resimulate

    path = tmp_path / 'run.mcap'
    ns = f'{NAMESPACE}_rec_{int(sig)}'
    process = NodeProcess('-p', f'record_path:={path}', '-p', 'seed:=4', namespace=ns)
    client = Client(ns)
    try:
        client.connect()
        reset_and_wait(client, 1, seed=9)
        for i in range(1, 6):
            assert step(client, 1, i, i % 3).info == ''
    finally:
        client.close()
        code, output = process.stop(sig)
    assert code == 0, output[-2000:]
    assert 'Traceback' not in output, output[-2000:]
    report = resimulate(path)
    assert report.ok, (report.mismatch, report.warnings)
    assert report.episodes >= 2 and report.steps >= 5, report


# ----------------------------------------------------------------------------- 11. signals
# A signal before the node's handlers are in place gets the default action (and no file exists
# yet): the tests wait for that event, read from /proc, not for a guessed import time.
def catches(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler of its own for ``sig`` now (SigCgt, proc(5))."""
    with open(f'/proc/{pid}/status') as f:
        caught = next(line for line in f if line.startswith('SigCgt:'))
    return bool(int(caught.split()[1], 16) >> (sig - 1) & 1)


@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
@pytest.mark.parametrize('delay_s', [0.1, 0.6])
def test_sigterm_during_start_up_exits_cleanly(delay_s: float) -> None:
    proc = subprocess.Popen([sim_node_executable(), '--ros-args', '-r',
                             f'__ns:={NAMESPACE}_early'],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_until(lambda: proc.poll() is not None or catches(proc.pid, signal.SIGTERM),
                   TIMEOUT_S * 3, 'sim_node handles SIGTERM')
        # Deliberately this long after: within rclpy's and the node's start-up (a second or
        # more), which is the case tested; nothing is assumed to have happened by then.
        time.sleep(delay_s)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, (proc.returncode, err[-2000:])
    assert 'Traceback' not in err, err[-2000:]


# Closing (issue 24 items 4, 5): run in child processes, signals and all, with faults injected.
CLOSING_PROBE = """
import json, os, signal, sys
from growspace_sim.node import main as node_main

seen = {}


class Probe:
    '''A node with a 1 kHz timer that notes whether its context was up at each call.'''

    def __init__(self, transport):
        self.transport, self.calls = transport, []
        transport.create_timer(0.001, self.tick)

    def tick(self):
        self.calls.append(self.transport.context.ok())
        if len(self.calls) == 200:  # the signal comes while the timer runs, however slow
            os.kill(os.getpid(), signal.SIGINT)

    def close(self):
        seen.update(up_at_close=self.transport.context.ok(), calls=len(self.calls),
                    calls_after_shutdown=self.calls.count(False))


def run(argv, stop):
    return node_main.run_node('probe', 'probe', argv, stop, Probe)


code = node_main.console_main(run, ['--ros-args', '-r', '__ns:=' + sys.argv[1]])
print(json.dumps({**seen, 'code': code}))
"""

HANGING_CLOSE = """
import sys, time
import rclpy.node
from growspace_sim.node import main as node_main


def destroy_node(self):  # a close that never returns
    time.sleep(3600)


rclpy.node.Node.destroy_node = destroy_node
node_main.CLOSE_TIMEOUT_S = float(sys.argv[2])
sys.exit(node_main.main(['--ros-args', '-r', '__ns:=' + sys.argv[1], '-p', 'mode:=realtime',
                         '-p', 'rate_hz:=100.0']))
"""


def test_a_signal_leaves_the_context_up_until_the_node_is_closed() -> None:
    from conftest import child_env

    out = subprocess.run([sys.executable, '-c', CLOSING_PROBE, f'{NAMESPACE}_probe'],
                         capture_output=True, text=True, timeout=TIMEOUT_S, env=child_env())
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen['code'] == 0 and seen['calls'] >= 200  # the timer ran until the signal
    assert seen['up_at_close'] and seen['calls_after_shutdown'] == 0
    assert 'context is invalid' not in out.stderr and 'Traceback' not in out.stderr


def _start_hanging_node(ns: str, close_timeout_s: float) -> tuple[subprocess.Popen, Any]:
    from conftest import child_env

    log = tempfile.TemporaryFile('w+')
    proc = subprocess.Popen([sys.executable, '-c', HANGING_CLOSE, ns, str(close_timeout_s)],
                            stdout=log,
                            stderr=subprocess.STDOUT, text=True, env=child_env())
    deadline = time.monotonic() + TIMEOUT_S
    while 'realtime mode' not in _read(log):
        assert proc.poll() is None and time.monotonic() < deadline, _read(log)[-2000:]
        time.sleep(0.05)
    return proc, log


def _read(log: Any) -> str:
    log.seek(0)
    return log.read()


@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
@pytest.mark.parametrize('second', [None, signal.SIGTERM], ids=['watchdog', 'second-signal'])
def test_closing_that_hangs_is_bounded(second: int | None) -> None:
    # With a second signal, a watchdog that cannot fire first: only the signal ends it.
    proc, log = _start_hanging_node(f'{NAMESPACE}_hang_{second or 0}',
                                    2.0 if second is None else 600.0)
    try:
        proc.send_signal(signal.SIGINT)
        start = time.monotonic()
        if second is not None:
            # The first signal was handled (the node put the default action back for the
            # next): closing has begun, and hangs.
            wait_until(lambda: not catches(proc.pid, second), TIMEOUT_S,
                       'the node handles the first signal')
            proc.send_signal(second)
        proc.wait(timeout=TIMEOUT_S)  # never, before: spinning in destroy_node, deaf to SIGTERM
        took = time.monotonic() - start
        text = _read(log)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        log.close()
    if second is None:  # the watchdog: every thread's stack, then exit 1
        assert proc.returncode == 1 and took > 1.5, (proc.returncode, took, text[-3000:])
        assert 'Timeout' in text and 'destroy_node' in text and 'run_node' in text, text[-3000:]
    else:  # the second signal's default action, at once
        assert proc.returncode == -second, (proc.returncode, took)
