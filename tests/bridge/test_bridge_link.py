"""The bridge's reply matching on an in-memory transport: late, duplicate and missing replies."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from growspace_gym_bridge import BridgeTimeout
from growspace_gym_bridge.link import ChamberLink
from growspace_sim.node.fake import FakeTransport
from growspace_sim.ros import convert
from growspace_sim.ros import types

NS = '/chamber'


class ScriptedTransport(FakeTransport):
    """Each spin delivers the next queued batch of messages, as if they had just arrived."""

    def __init__(self) -> None:
        super().__init__('client', NS)
        self.batches: list[list[tuple[str, Any]]] = []

    @property
    def queue(self) -> list[tuple[str, Any]]:
        return [m for batch in self.batches for m in batch]

    @queue.setter
    def queue(self, messages: list[tuple[str, Any]]) -> None:
        self.batches = [messages]

    def spin_once(self, timeout_s: float) -> None:
        for topic, msg in self.batches.pop(0) if self.batches else ():
            self.inject(topic, msg)


def result(reset_id: int, step_id: int, stamp: int) -> tuple[str, Any]:
    return 'step_result', types.new(types.STEP_RESULT, header=convert.header(stamp, 'c'),
                                    reset_id=reset_id, step_id=step_id, step=step_id)


def outputs(stamp: int, fill: int) -> list[tuple[str, Any]]:
    image = convert.image_msg(np.full((4, 4, 3), fill, np.uint8), stamp, 'cam')
    plant = types.new(types.PLANT_STATE, header=convert.header(stamp, 'c'), step=fill)
    light = types.new(types.LIGHT_COMMAND, header=convert.header(stamp, 'c'), x=float(fill))
    return [('camera/image_raw', image), ('plant/state', plant), ('light/state', light)]


def test_late_and_duplicate_replies_are_never_taken_for_the_current_step() -> None:
    transport = ScriptedTransport()
    link = ChamberLink(transport)
    transport.queue = [result(10, 2, 100), *outputs(100, 2),  # late: the previous step
                       result(9, 3, 110),  # same step id, another episode
                       *outputs(130, 3), result(10, 3, 130), result(10, 3, 130)]  # + duplicate
    reply = link.step(10, 3, timeout_s=1.0)
    assert convert.to_ns(reply.result.header.stamp) == 130
    assert set(reply.image.data) == {3} and reply.plant.step == 3 and reply.light.x == 3.0
    assert link.stale == 3
    transport.queue = [*outputs(100, 2), result(10, 3, 130), *outputs(140, 4),
                       result(10, 4, 140)]  # stale outputs and result arrive again first
    reply = link.step(10, 4, timeout_s=1.0)
    assert set(reply.image.data) == {4} and reply.plant.step == 4 and link.stale == 4


def test_outputs_arriving_after_their_result_are_waited_for() -> None:
    transport = ScriptedTransport()
    link = ChamberLink(transport)
    image, plant, light = outputs(50, 1)
    transport.batches = [[result(1, 1, 50), plant], [], [image], [light]]
    reply = link.step(1, 1, timeout_s=1.0)
    assert set(reply.image.data) == {1} and reply.light.x == 1.0 and not transport.batches


def test_a_missing_result_or_output_times_out_naming_topic_and_step() -> None:
    transport = ScriptedTransport()
    link = ChamberLink(transport)
    with pytest.raises(BridgeTimeout, match=r'^/chamber/step_result: no reply to light/command '
                       r'for step_id 5 \(reset_id 2\) within the timeout of 0.1 s$'):
        link.step(2, 5, timeout_s=0.1)
    transport.queue = [result(2, 6, 70), *outputs(70, 6)[1:]]  # the image never comes
    with pytest.raises(BridgeTimeout, match=r'^/chamber/camera/image_raw: the step result '
                       r'came but not this output .*step_id 6') as caught:
        link.step(2, 6, timeout_s=0.1)
    assert (caught.value.step_id, caught.value.reset_id, caught.value.timeout_s) == (6, 2, 0.1)


def test_error_results_come_back_without_observations() -> None:
    transport = ScriptedTransport()
    link = ChamberLink(transport, with_state=False)
    error = result(4, 1, 90)
    error[1].info = 'error: action = 9 is not allowed'
    transport.queue = [error]
    reply = link.step(4, 1, timeout_s=1.0)
    assert reply.result.info.startswith('error') and reply.image is None
