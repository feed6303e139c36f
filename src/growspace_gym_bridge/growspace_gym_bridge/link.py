"""The lockstep protocol of a chamber node, client side, over any node ``Transport``.

A request (reset or step) is answered by a ``StepResult`` carrying its (reset_id, step_id),
published last, after the image, plant state and light state of the same step. The image has
no id, so outputs are matched by their header stamp: sim time rises at every step and reset,
so the result's stamp names the step's image and states. Anything with other ids or stamps is
a late or duplicate reply and is dropped, never taken for the current step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import json
import time
from typing import Any

import numpy as np
from growspace_sim.ros import convert
from growspace_sim.ros import qos as ros_qos, types
from growspace_sim.ros.interface import COMMAND_QOS, OBSERVATION_QOS

RESULT, IMAGE, PLANT, LIGHT, CONFIG = 'step_result', 'camera/image_raw', 'plant/state', \
    'light/state', 'chamber/config'
STATE_TOPICS = (PLANT, LIGHT)
SPIN_S = 0.05  # longest blocking wait between two checks of the node's health [s]
MAX_BUFFERED = 64  # outputs kept per topic while their StepResult is on its way
# Matching is seen by each side on its own: after ours, the node may still skip an output for a
# reader it has not matched yet (chamber_node._wanted), so wait a little longer.
SETTLE_S = 0.1

_NO_FLOATS = np.zeros(0, np.float32)
Liveness = Callable[[Callable[[], str]], None]  # raises NodeDied naming what was awaited


@dataclass
class Reply:
    """What the node sent for one request; observations are None after an error result."""

    result: Any  # growspace_msgs/StepResult
    image: Any | None = None  # sensor_msgs/Image
    plant: Any | None = None  # growspace_msgs/PlantState
    light: Any | None = None  # growspace_msgs/LightCommand (applied light)
    config: dict[str, Any] | None = None  # chamber/config of this reset, if awaited


class ChamberLink:
    """Client endpoints of one chamber: send resets and commands, collect matching replies.

    Args:
        transport: the middleware seam of ``growspace_sim.node`` (``RclpyTransport`` or an
            in-process one), in the chamber's namespace.
        with_state: also read ``plant/state`` and ``light/state`` (for ``info``); without
            them the node does not even build them.
        with_image: wait for the step's image (a chamber without a camera, the LED gantry run
            without ``camera``, answers with ``light/state`` and ``step_result`` only).
        liveness: called while waiting; raises if the node is known to be gone.
    """

    def __init__(self, transport: Any, with_state: bool = True,
                 liveness: Liveness | None = None, with_image: bool = True) -> None:
        self.transport = transport
        self.liveness = liveness or (lambda describe: None)
        self.with_state = with_state
        self.with_image = with_image
        self.stale = 0  # late or duplicate replies dropped
        self._expect: tuple[int, int] | None = None  # (reset_id, step_id) awaited
        self._result: Any = None
        self._frames: dict[str, dict[int, Any]] = {IMAGE: {}, PLANT: {}, LIGHT: {}}
        self._configs: dict[int, dict[str, Any]] = {}
        self.config: dict[str, Any] | None = None  # latest chamber/config
        self._command = transport.publisher(types.LIGHT_COMMAND, 'light/command', COMMAND_QOS)
        self._command_msg = types.new(types.LIGHT_COMMAND)
        self._reset = transport.publisher(types.RESET_REQUEST, 'reset', COMMAND_QOS)
        transport.subscribe(types.STEP_RESULT, RESULT, OBSERVATION_QOS, self._on_result)
        if with_image:
            transport.subscribe(types.IMAGE, IMAGE, OBSERVATION_QOS,
                                self._frame_callback(IMAGE))
        if with_state:
            transport.subscribe(types.PLANT_STATE, PLANT, OBSERVATION_QOS,
                                self._frame_callback(PLANT))
            transport.subscribe(types.LIGHT_COMMAND, LIGHT, OBSERVATION_QOS,
                                self._frame_callback(LIGHT))
        transport.subscribe(types.STRING, CONFIG, ros_qos.LATCHED, self._on_config)

    @property
    def inputs(self) -> tuple[str, ...]:
        return 'light/command', 'reset'

    @property
    def outputs(self) -> tuple[str, ...]:
        return self._awaited(RESULT)

    def _awaited(self, *first: str) -> tuple[str, ...]:
        """The outputs of one step this link waits for (after ``first``)."""
        if self.with_image:
            return (*first, IMAGE, *(STATE_TOPICS if self.with_state else ()))
        return (*first, *((LIGHT,) if self.with_state else ()))

    # --- callbacks (never raise: the transport would only log it) -----------------------

    def _on_result(self, msg: Any, cdr: bytes) -> None:
        if self._expect == (int(msg.reset_id), int(msg.step_id)) and self._result is None:
            self._result = msg
        else:
            self.stale += 1

    def _frame_callback(self, topic: str) -> Callable[[Any, bytes], None]:
        frames = self._frames[topic]

        def store(msg: Any, cdr: bytes) -> None:
            frames[convert.to_ns(msg.header.stamp)] = msg
            if len(frames) > MAX_BUFFERED:  # nobody collects them: keep the newest
                del frames[min(frames)]
        return store

    def _on_config(self, msg: Any, cdr: bytes) -> None:
        try:
            config = json.loads(msg.data)
            reset_id = int(config['reset_id'])
        except (ValueError, KeyError, TypeError):
            self.stale += 1
            return
        self.config = config
        self._configs[reset_id] = config
        while len(self._configs) > MAX_BUFFERED:
            del self._configs[min(self._configs)]

    # --- connection ----------------------------------------------------------------------

    def connect(self, timeout_s: float) -> dict[str, Any]:
        """Wait until the node's endpoints match ours and its latched config arrived.

        Returns:
            The node's ``chamber/config`` (parsed JSON).

        Raises:
            BridgeTimeout: naming the first topic that did not match in time.
            NodeDied: the node exited meanwhile.
        """
        from growspace_gym_bridge.errors import BridgeTimeout

        deadline = time.monotonic() + timeout_s
        pending = [*self.inputs, *self.outputs, CONFIG]
        while pending or self.config is None:
            pending = [t for t in pending if not self.transport.matched(t)]
            if not pending and self.config is not None:
                break
            if time.monotonic() >= deadline:
                topic = pending[0] if pending else CONFIG
                detail = 'no matching endpoint of the sim node' if pending else \
                    'no latched configuration'
                raise BridgeTimeout(self.transport.resolve(topic), timeout_s, detail=detail)
            self.liveness(lambda: f'the node to connect on {self.transport.resolve(RESULT)}')
            self.transport.spin_once(0.01)
        settle = time.monotonic() + SETTLE_S
        while time.monotonic() < settle:
            self.liveness(lambda: 'the node to connect')
            self.transport.spin_once(min(SPIN_S, max(0.0, settle - time.monotonic())))
        return self.config

    def node_present(self) -> bool:
        """Whether the node's step_result writer is still matched (for attached nodes)."""
        return self.transport.matched(RESULT)

    # --- requests ------------------------------------------------------------------------

    def reset(self, reset_id: int, seed: int | None, challenge: str, setting: str,
              timeout_s: float, with_config: bool = False) -> Reply:
        """Send a ``ResetRequest`` and wait for its observation.

        Args:
            reset_id: id of the new episode (unique for this client).
            seed: seed of the episode, or None to continue the node's random stream.
            challenge: challenge to switch to ('' keeps the node's).
            setting: setting to switch to ('' keeps the node's).
            timeout_s: how long to wait [s].
            with_config: also wait for the ``chamber/config`` of this reset.

        Raises:
            BridgeTimeout, NodeDied: see ``wait``.
        """
        msg = types.new(types.RESET_REQUEST, reset_id=reset_id, has_seed=seed is not None,
                        seed=0 if seed is None else seed, challenge=challenge, setting=setting)
        self._expect, self._result = (reset_id, 0), None
        self._reset(msg)
        return self.wait(timeout_s, 'reset', with_config)

    def step(self, reset_id: int, step_id: int, timeout_s: float, *, action: int = 0,
             continuous: Any = None) -> Reply:
        """Send one lockstep ``LightCommand`` (discrete, or continuous if given) and wait."""
        msg = self._command_msg  # reused: types.new costs more than the rest of a send
        msg.step_id = step_id
        if continuous is None:
            msg.mode, msg.action, msg.continuous = convert.MODE_DISCRETE, action, _NO_FLOATS
        else:
            msg.mode, msg.action = convert.MODE_CONTINUOUS, 0
            msg.continuous = np.asarray(continuous, np.float32).reshape(-1)
        self._expect, self._result = (reset_id, step_id), None
        self._command(msg)
        return self.wait(timeout_s, 'light/command')

    def wait(self, timeout_s: float, request: str, with_config: bool = False) -> Reply:
        """Spin until the awaited result and the outputs with its stamp are all in.

        Raises:
            BridgeTimeout: naming the topic still missing, the step id and the timeout.
            NodeDied: the node exited meanwhile.
        """
        from growspace_gym_bridge.errors import BridgeTimeout

        assert self._expect is not None, 'wait() without a request'
        reset_id, step_id = self._expect
        deadline = time.monotonic() + timeout_s
        wanted = self._awaited()
        while True:
            result = self._result
            missing = RESULT
            if result is not None:
                if result.info:  # an error or 'episode over': nothing else was published
                    return self._finish(Reply(result))
                stamp = convert.to_ns(result.header.stamp)
                missing = next((t for t in wanted if stamp not in self._frames[t]), '')
                if not missing and with_config and reset_id not in self._configs:
                    missing = CONFIG
                if not missing:
                    reply = Reply(result, *(self._frames[t].get(stamp) for t in
                                            (IMAGE, PLANT, LIGHT)))
                    reply.config = self._configs.get(reset_id) if with_config else None
                    return self._finish(reply, stamp)
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                detail = 'no reply' if missing == RESULT else \
                    'the step result came but not this output'
                raise BridgeTimeout(self.transport.resolve(missing), timeout_s, step_id,
                                    reset_id, f'{detail} to {request}')
            self.liveness(lambda topic=missing: f'{self.transport.resolve(topic)} '
                          f'(step_id {step_id}, reset_id {reset_id})')
            self.transport.spin_once(min(remaining, SPIN_S))

    def _finish(self, reply: Reply, stamp: int | None = None) -> Reply:
        self._expect, self._result = None, None
        if stamp is not None:  # everything up to this step is now late
            for frames in self._frames.values():
                for old in [s for s in frames if s <= stamp]:
                    del frames[old]
        return reply
