"""``view_node``: 3D markers and a human-size image of a chamber, beside the node that runs it.

Subscribes, in its namespace, to ``chamber/config``, ``plant/state``, ``light/state`` and
``step_result`` (so it serves a live ``sim_node``, a ``growspace-replay play`` and the gantry
alike) and publishes, only while someone subscribes, one frame per ``step_result``:

| topic | type | QoS |
|---|---|---|
| ``plant/markers`` | visualization_msgs/MarkerArray, frame ``chamber`` | reliable, keep_last 10 |
| ``camera/image_view`` | sensor_msgs/Image, rgb8, ``view_size`` px wide | reliable, keep_last 10 |

Drawing happens here, never in the simulator's step. Parameters: ``view_size`` (px, default
512), ``foxglove_port`` (0 = no Foxglove server, the default), ``foxglove_address`` (default
127.0.0.1). With a port, ``view.foxglove_server`` serves the chamber's topics and these two over
the Foxglove WebSocket protocol and forwards client commands on ``light/command`` and ``reset``.

A message the view cannot use is dropped with a throttled warning naming the field and value;
the node never stops for bad input. Exit codes: 0 after SIGINT/SIGTERM, 2 for a bad parameter.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
import sys
import threading
from typing import Any

from growspace_sim.core.schema import Bounds, param
from growspace_sim.node import params
from growspace_sim.node.main import console_main, run_node
from growspace_sim.node.presence import ChamberWatch
from growspace_sim.node.transport import Transport
from growspace_sim.ros import convert, qos as ros_qos, types
from growspace_sim.ros.interface import COMMAND_QOS, OBSERVATION_QOS
from growspace_sim.simulation import warm_up
from growspace_sim.view import markers
from growspace_sim.view.image import DEFAULT_SIZE, ViewRenderer
from growspace_sim.view.scene import Scene, ViewInputError

NODE_NAME = 'growspace_view'
MARKERS_TOPIC = 'plant/markers'
IMAGE_TOPIC = 'camera/image_view'
RESET_WAIT_S = 5.0  # how long a Foxglove reset call waits for the chamber's answer [s]
# The view re-simulates from every light/state in turn, so a burst it is slow to read must wait
# in its queue rather than be dropped: 100 messages, 2 s of a 50 Hz chamber.
STEP_INPUT_QOS = ros_qos.QosProfile(depth=100)
# (key, topic, type, QoS) of what the view reads; the image is forwarded to Foxglove only.
INPUTS = (
    ('config', 'chamber/config', types.STRING, ros_qos.LATCHED),
    ('plant', 'plant/state', types.PLANT_STATE, STEP_INPUT_QOS),
    ('light', 'light/state', types.LIGHT_COMMAND, STEP_INPUT_QOS),
    ('result', 'step_result', types.STEP_RESULT, STEP_INPUT_QOS),
)
FOXGLOVE_ONLY = (('image', 'camera/image_raw', types.IMAGE, OBSERVATION_QOS),)


class ViewNode:
    """The view's logic over a ``Transport``.

    Args:
        transport: the middleware (``RclpyTransport`` for ``view_node``).
        view_size: width of the view image [px].
        foxglove: builds the Foxglove server from (outputs, inputs, on_input, services), or
            None for no server.

    Raises:
        ValueError: a view size out of range.
    """

    def __init__(self, transport: Transport, view_size: int = DEFAULT_SIZE,
                 foxglove: Callable[..., Any] | None = None) -> None:
        self.transport = transport
        self.log = transport.logger
        self.scene = Scene()
        self.renderer = ViewRenderer(view_size)
        self.frames = 0  # frames built (for tests and the log)
        self.configs = 0  # chamber/config messages received (the chamber showed itself)
        self._note = None
        self._publish_markers = transport.publisher(markers.MARKER_ARRAY, MARKERS_TOPIC,
                                                    OBSERVATION_QOS)
        self._publish_image = transport.publisher(types.IMAGE, IMAGE_TOPIC, OBSERVATION_QOS)
        self._reset_done = threading.Condition()
        self._resets: dict[int, str] = {}  # reset_id -> info of its step_result
        self._next_reset_id = 1 << 40  # far from the ids an RL client counts up from 0
        self.fox = None
        if foxglove is not None:
            self._publish_command = transport.publisher(types.LIGHT_COMMAND, 'light/command',
                                                        COMMAND_QOS)
            self._publish_reset = transport.publisher(types.RESET_REQUEST, 'reset', COMMAND_QOS)
            self._publish_lock = threading.Lock()
            outputs = [(transport.resolve(t), n) for _, t, n, _ in INPUTS + FOXGLOVE_ONLY]
            outputs += [(transport.resolve(MARKERS_TOPIC), markers.MARKER_ARRAY),
                        (transport.resolve(IMAGE_TOPIC), types.IMAGE)]
            inputs = {transport.resolve('light/command'): types.LIGHT_COMMAND,
                      transport.resolve('reset'): types.RESET_REQUEST}
            services = {transport.resolve('reset'): (types.RESET, self.reset_service)}
            self.fox = foxglove(outputs, inputs, self.on_client_message, services=services)
        handlers = {'config': self._on_config,
                    'plant': self.scene.on_plant, 'light': self.scene.on_light,
                    'result': self._on_result,
                    'image': lambda msg: None}
        for key, topic, typename, qos in INPUTS + (FOXGLOVE_ONLY if self.fox else ()):
            transport.subscribe(typename, topic, qos,
                                self._receiver(transport.resolve(topic), handlers[key]))

    def _receiver(self, topic: str, handle: Callable[[Any], Any]) -> Callable[[Any, bytes], None]:
        def receive(msg: Any, cdr: bytes) -> None:
            if self.fox is not None and self.fox.wants(topic):
                self.fox.log(topic, cdr)
            try:
                handle(msg)
            except ViewInputError as e:
                self.log.warn(f'input:{e.topic}:{e.field}', str(e))
        return receive

    def _on_config(self, msg: Any) -> None:
        self.configs += 1
        self.scene.on_config(msg.data)

    def _on_result(self, msg: Any) -> None:
        with self._reset_done:
            if int(msg.step_id) == 0 and int(msg.reset_id) >= 1 << 40:
                self._resets[int(msg.reset_id)] = msg.info
                self._reset_done.notify_all()
        frame = self.scene.on_result(msg)
        if self.scene.note != self._note:
            self._note = self.scene.note
            if self._note:
                self.log.info(f'view: no photons shown: {self._note}')
        want_markers = self._wanted(MARKERS_TOPIC)
        want_image = self._wanted(IMAGE_TOPIC)
        if not (want_markers or want_image):
            return
        self.frames += 1
        if want_markers:
            self._send(MARKERS_TOPIC, self._publish_markers,
                       markers.marker_array(frame, self.scene.frame_id))
        if want_image:
            self._send(IMAGE_TOPIC, self._publish_image, convert.image_msg(
                self.renderer.render(frame), frame.stamp_ns, self.scene.image_frame_id))

    def _wanted(self, topic: str) -> bool:
        if self.transport.has_subscribers(topic):
            return True
        return self.fox is not None and self.fox.wants(self.transport.resolve(topic))

    def _send(self, topic: str, publish: Callable[[Any], bytes], msg: Any) -> None:
        cdr = publish(msg)
        if self.fox is not None:
            name = self.transport.resolve(topic)
            if self.fox.wants(name):
                self.fox.log(name, cdr)

    # --- Foxglove clients (called in the server's threads) -------------------------------

    def on_client_message(self, topic: str, msg: Any) -> None:
        """Forward a Foxglove client's LightCommand or ResetRequest to the chamber."""
        publish = (self._publish_command if topic == self.transport.resolve('light/command')
                   else self._publish_reset)
        with self._publish_lock:
            publish(msg)

    def reset_service(self, request: Any) -> Any:
        """The chamber's Reset service for Foxglove: sent as a ``reset`` request, answered from
        the chamber's step_result for it (waits at most ``RESET_WAIT_S``)."""
        with self._reset_done:
            reset_id = self._next_reset_id
            self._next_reset_id += 1
        msg = types.new(types.RESET_REQUEST, reset_id=reset_id, has_seed=request.has_seed,
                        seed=request.seed, challenge=request.challenge, setting=request.setting)
        with self._publish_lock:
            self._publish_reset(msg)
        with self._reset_done:
            done = self._reset_done.wait_for(lambda: reset_id in self._resets, RESET_WAIT_S)
            info = self._resets.pop(reset_id, None)
        if not done:
            message = f'no answer from the chamber within {RESET_WAIT_S} s'
        else:
            message = info or ''
        ok = done and not info
        return types.new(types.RESET_SRV_RESPONSE, success=ok, message=message,
                         reset_id=reset_id if ok else 0)

    def close(self) -> None:
        if self.fox is not None:
            self.fox.close()


@dataclass(frozen=True)
class ViewParams:
    """Settings of view_node (ROS parameters of the same names, read at start-up)."""

    view_size: int = param(DEFAULT_SIZE, 'width of camera/image_view', unit='px',
                           bounds=Bounds(16, 4096, integer=True))
    foxglove_port: int = param(0, 'TCP port of the Foxglove WebSocket server; 0 = no server',
                               bounds=Bounds(0, 65535, integer=True))
    foxglove_address: str = param('127.0.0.1', 'address the Foxglove server binds; another '
                                  'address lets anyone who reaches it watch and drive the light')

    def __post_init__(self) -> None:
        params.check(self)


def foxglove_factory(settings: ViewParams) -> Callable[..., Any]:
    """What builds ``view.foxglove_server.FoxgloveServer`` on the parameters' address, port."""
    from growspace_sim.view.foxglove_server import FoxgloveServer

    def build(*args: Any, **kwargs: Any) -> FoxgloveServer:
        return FoxgloveServer(*args, host=settings.foxglove_address,
                              port=settings.foxglove_port, **kwargs)
    return build


def run(argv: Sequence[str], stop: threading.Event) -> int:
    """Run the view node until SIGINT/SIGTERM (or ``stop``)."""
    def start(transport: Any) -> ViewNode:
        values, unknown = transport.declare_parameters(
            params.specs_of(ViewParams, runtime=False), params.check_type)
        if unknown:
            transport.logger.warn('params:unknown', f'ignored unknown parameter(s) {unknown}: '
                                  'not parameters of view_node (a typo?).')
        settings = ViewParams(**values)
        # The view re-simulates the chamber: load the compiled kernels before subscribing, or
        # the first frame's load stalls the inputs long enough to drop a burst of them.
        warm_up()
        view = ViewNode(transport, settings.view_size,
                        foxglove_factory(settings) if settings.foxglove_port else None)
        watch = ChamberWatch(transport, 'view_node', lambda text: transport.logger.warn(
            'no-chamber', text))

        def look() -> None:
            if view.configs:
                watch.seen()
            watch.check()
        transport.create_timer(1.0, look)
        where = '' if view.fox is None else \
            f', Foxglove on ws://{view.fox.host}:{view.fox.port}'
        transport.logger.info(f'view_node {transport.resolve("~")}: {settings.view_size} px'
                              + where)
        return view
    return run_node('view_node', NODE_NAME, argv, stop, start,
                    bad_input=(ValueError, RuntimeError))


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``view_node``."""
    return console_main(run, argv)


if __name__ == '__main__':
    sys.exit(main())
