"""The gantry's side of the camera seam: a lockstep step's photo, asked for once the move is done.

After a reached move (or a reset's), the step is not answered at once: the photo light goes on
(``photo_light``: ``M8``, then ``photo_settle_s``), the camera's capture service
(``growspace_msgs/srv/Capture``, camera_node) is called with the step's stamp, ids, the
episode's config, the light as reached and the episode's target, and the step is answered when
the camera answers (docs/architecture.md, the rig). The call is asynchronous on the transport:
the node's 10 ms safety loop goes on meanwhile, and polls ``Photographer.poll``.

What the step's answer then holds (``outputs``): a photo the camera measured gives
``camera/image_raw``, ``plant/state``, ``light/state``, ``camera/photo``,
``camera/measurement`` and the reward; a photo the camera refused (``ok`` false), an answer that
does not hold what ``ok`` promises, no service or no answer within ``capture_timeout_s`` give
``light/state`` (and the photo and measurement when there are any) and a step_result with
``info = "error: camera: <code>: <why>"``: never an image or a reward the photo did not give.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
import math
from typing import Any

import numpy as np

from growspace_sim.core.chamber import StepOutcome
from growspace_sim.core.config import SimConfig
from growspace_sim.ros import convert, types

# Why the gantry got no measurement (the camera's own codes are CameraMeasurement.error_code).
UNAVAILABLE = 'unavailable'  # no capture service within capture_timeout_s
TIMEOUT = 'timeout'  # asked, and no answer within capture_timeout_s
BAD_ANSWER = 'bad_answer'  # an answer that does not hold what it claims
LIGHT, SETTLE, SERVICE, ASKED = 'photo light', 'settling', 'waiting for the service', 'asked'


@dataclass
class Shot:
    """One step's photo in progress.

    Attributes:
        reset_id, step_id: The step it answers.
        stamp: The step's stamp [ns], on every output.
        light: The reached light (LightCommand), published as the step's ``light/state``.
        request: The Capture request.
        deadline: When it fails [s, the node's clock].
        phase: ``LIGHT`` (waiting for GRBL's ``ok`` to ``M8``), ``SETTLE``, ``SERVICE``
            (waiting for the capture service to be there) or ``ASKED``.
        settle_until: When the photo light has settled [s].
        cancel: Cancels the call once asked.
    """

    reset_id: int
    step_id: int
    stamp: int
    light: Any
    request: Any
    deadline: float
    phase: str
    settle_until: float = 0.0
    cancel: Callable[[], None] = field(default=lambda: None, repr=False)


Answer = Callable[[Shot, Any, str], None]  # (shot, Capture response or None, failure or '')


class Photographer:
    """The photo of each lockstep step, asked of the camera without ever blocking.

    Args:
        transport: The node's transport (its ``client`` calls the service).
        controller: The GRBL controller (its photo light, if it has one).
        service: The capture service name (``GantryParams.camera``).
        timeout_s: ``capture_timeout_s``: from the reached move to the camera's answer, the
            photo light's settle time not counted.
        settle_s: ``photo_settle_s``, after GRBL accepted ``M8`` (with a photo light only).
        answer: Called once per photo that ends with the camera's answer or a failure ('' or
            '<code>: <why>'); never for a photo dropped by ``abandon``.
    """

    def __init__(self, transport: Any, controller: Any, service: str, timeout_s: float,
                 settle_s: float, answer: Answer) -> None:
        self.client = transport.client(types.CAPTURE, service)
        self.service = transport.resolve(service)
        self.controller = controller
        self.timeout_s, self.settle_s = timeout_s, settle_s
        self.answer = answer
        self.shot: Shot | None = None

    @property
    def busy(self) -> bool:
        """A photo is under way (its step is not answered yet)."""
        return self.shot is not None

    @property
    def phase(self) -> str:
        """Where the photo in progress is (``gantry/status``); 'idle' without one."""
        return 'idle' if self.shot is None else self.shot.phase

    def start(self, reset_id: int, step_id: int, stamp: int, light: Any, request: Any,
              now: float) -> None:
        """Begin the photo of a reached move: the photo light first, if the rig has one."""
        lit = self.controller.has_photo_light
        self.shot = Shot(reset_id, step_id, stamp, light, request,
                         now + self.timeout_s + (self.settle_s if lit else 0.0),
                         LIGHT if lit else SERVICE)
        if lit:
            self.controller.set_photo_light(True)  # M8 at the next Idle, before anything else
        self.poll(now)

    def poll(self, now: float) -> None:
        """Advance the photo in progress (the node's 10 ms loop calls this; never waits)."""
        shot = self.shot
        if shot is None:
            return
        if shot.phase == LIGHT and self.controller.photo_light_on():
            shot.phase, shot.settle_until = SETTLE, now + self.settle_s
        if shot.phase == SETTLE and now >= shot.settle_until:
            shot.phase = SERVICE
        if shot.phase == SERVICE and self.client.ready():
            shot.phase = ASKED
            shot.cancel = self.client.call(shot.request,
                                           lambda response: self._answered(shot, response))
        if self.shot is shot and now > shot.deadline:
            self._end(shot, None, self._late(shot.phase))

    def abandon(self) -> Shot | None:
        """Drop the photo in progress (a fault, a newer command, shutdown): the photo light is
        switched off and a late answer is ignored. Returns the dropped photo, if any."""
        shot, self.shot = self.shot, None
        if shot is not None:
            shot.cancel()
            self.controller.set_photo_light(False)
        return shot

    def _late(self, phase: str) -> str:
        within = f'within capture_timeout_s = {self.timeout_s:g} s'
        if phase == ASKED:
            return f'{TIMEOUT}: no answer from {self.service} {within}'
        if phase == SERVICE:
            return f'{UNAVAILABLE}: no {self.service} service {within} (is camera_node ' \
                f'running in this namespace?)'
        return f'{TIMEOUT}: the controller did not accept the photo light (M8) {within}'

    def _answered(self, shot: Shot, response: Any) -> None:
        if self.shot is shot:  # else a late answer to a photo abandoned or timed out
            shot.cancel = _answered_already
            self._end(shot, response, '')

    def _end(self, shot: Shot, response: Any, failure: str) -> None:
        self.abandon()
        self.answer(shot, response, failure)


def _answered_already() -> None:
    """Nothing to cancel: the call was answered."""


def capture_request(stamp: int, step_id: int, step: int, config: str, light: Any,
                    cfg: SimConfig, target: complex | None, mask: np.ndarray | None,
                    frame_id: str) -> Any:
    """A ``Capture`` request for a step: its stamp, ids, the episode's ``chamber/config``, the
    reached light (LightCommand) and the episode's target (a point, or the shape's mask)."""
    point = target if cfg.task.digits is None else None
    shape = np.zeros(0, np.uint8) if mask is None or cfg.task.digits is None else \
        np.asarray(mask, np.uint8).reshape(-1)
    return types.new(f'{types.CAPTURE}_Request', header=convert.header(stamp, frame_id),
                     step_id=step_id, step=step, config=config, light=light,
                     has_point_target=point is not None,
                     target_x=0.0 if point is None else float(point.real),
                     target_z=0.0 if point is None else float(point.imag), target_mask=shape)


def outputs(response: Any, light: Any, stamp: int, cfg: SimConfig,
            failure: str = '') -> tuple[list[tuple[str, Any]], StepOutcome | None, str]:
    """What a Capture answer gives the step.

    Args:
        response: The camera's answer (None: none came, ``failure`` says why).
        light: The reached light (LightCommand at the step's stamp).
        stamp: The step's stamp [ns]: every output's header gets it.
        cfg: The episode's configuration (resolution, plants).
        failure: Why there is no answer ('' when there is one).

    Returns:
        The messages to publish before the step_result, as (key, message) in the simulator's
        order (image, plant, light, photo, measurement; image and plant only from a measured
        photo), the outcome (None when not measured) and the failure ('<code>: <why>', or '').
    """
    if response is None:
        return [('light', light)], None, failure
    m = response.measurement
    after = [*([('photo', response.photo)] if len(response.photo.data) else []),
             ('measurement', m)]
    if not m.ok:
        failure = f'{m.error_code or BAD_ANSWER}: ' \
            f'{m.error or "the camera refused the photo without a reason"}'
    else:
        failure = _unfit(response, cfg)
    for msg in (response.photo, m, response.observation, response.plant):
        msg.header.stamp = convert.stamp(stamp)
    if failure:
        return [('light', light), *after], None, failure
    outcome = StepOutcome(float(m.reward), np.asarray(m.plant_rewards, np.float64),
                          bool(m.success), False, 0)
    return [('image', response.observation), ('plant', response.plant), ('light', light),
            *after], outcome, ''


def _unfit(response: Any, cfg: SimConfig) -> str:
    """Why an answer that says ``ok`` cannot be used ('' if it can)."""
    m, image, res = response.measurement, response.observation, cfg.resolution
    if (image.height, image.width, image.encoding) != (res, res, 'rgb8') \
            or len(image.data) != res * res * 3:
        return f'{BAD_ANSWER}: measured, but the observation is {image.width} x ' \
            f'{image.height} {image.encoding!r}, not {res} x {res} rgb8'
    if not math.isfinite(m.reward) or len(m.plant_rewards) != cfg.plant_count \
            or not np.all(np.isfinite(m.plant_rewards)):
        return f'{BAD_ANSWER}: measured, but the reward {m.reward!r} or the plant rewards ' \
            f'{list(m.plant_rewards)!r} do not fit {cfg.plant_count} plant(s)'
    return ''
