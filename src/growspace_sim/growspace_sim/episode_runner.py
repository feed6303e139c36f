"""Drive a ``Simulation`` with an agent in-process and record exactly what ``sim_node`` publishes.

No middleware: each message is built by ``convert`` and serialised by ``ros.types`` as the node
does before publishing, then handed to an optional ``McapRecorder`` with the node's topic names,
QoS and stamps. The sample bags, the recording tests and the benchmark use it; replay reads its
files and the node's alike.

Message order (the node's contract, ``docs/recording.md``):
- reset: ``reset`` (the ResetRequest as received, when there was one), ``chamber/config``,
  ``/clock``, ``camera/image_raw``, ``plant/state``, ``light/state``, ``step_result`` (step 0);
- step: ``light/command`` (as received), ``/clock``, ``camera/image_raw``, ``plant/state``,
  ``light/state``, ``step_result``.

Time is simulated: tick k >= 1 (every step and every reset is one tick) is stamped
``k * 1 / rate_hz``; a received message is stamped half a period before the tick it causes, so
sorting by time keeps the order above. log_time = publish_time = the stamp.
"""

from __future__ import annotations

import logging
from typing import Any, Callable

import numpy as np

from growspace_sim import convert, recording
from growspace_sim.core.chamber import Chamber, StepOutcome
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import BEAM_ACTIONS, SPOT_ACTIONS
from growspace_sim.ros import names, qos as ros_qos, types
from growspace_sim.simulation import Simulation

STRING = 'std_msgs/msg/String'
DEFAULT_NAMESPACE = '/growspace'
DEFAULT_FRAME_ID = 'chamber'
NODE_NAME = 'growspace_sim'

# Topic (relative to the chamber namespace) -> (type, QoS). The node uses the same table.
TOPICS: dict[str, tuple[str, ros_qos.QosProfile]] = {
    'reset': (types.RESET_REQUEST, ros_qos.DEFAULT),
    'light/command': (types.LIGHT_COMMAND, ros_qos.DEFAULT),
    'chamber/config': (STRING, ros_qos.LATCHED),
    '/clock': (convert.CLOCK, ros_qos.CLOCK),
    'camera/image_raw': (convert.IMAGE, ros_qos.DEFAULT),
    'plant/state': (types.PLANT_STATE, ros_qos.DEFAULT),
    'light/state': (types.LIGHT_COMMAND, ros_qos.DEFAULT),
    'step_result': (types.STEP_RESULT, ros_qos.DEFAULT),
}

Policy = Callable[[np.ndarray, Any], Any]  # (observation, runner) -> discrete action

logger = logging.getLogger(__name__)


class EpisodeRunner:
    """A chamber in lockstep that records the node's messages.

    It quacks enough like a Gymnasium env (``unwrapped``, ``chamber``, ``continuous``) for
    ``agents.OracleAgent.act(observation, runner)``.

    Args:
        cfg: The starting configuration.
        recorder: Where messages go; None only builds and serialises them (the node's cost of
            publishing), which is the baseline of the recording benchmark.
        namespace: Chamber namespace the topics are resolved in.
        frame_id: ``header.frame_id`` of every stamped message.
        rate_hz: Steps per second of simulated time.
        digit_source: Shape targets' source (``digits.load_digits``).
    """

    continuous = False

    def __init__(self, cfg: SimConfig, recorder: recording.McapRecorder | None = None, *,
                 namespace: str = DEFAULT_NAMESPACE, frame_id: str = DEFAULT_FRAME_ID,
                 rate_hz: float = 10.0, digit_source: str = 'auto') -> None:
        if not rate_hz > 0:
            raise ValueError(f'rate_hz must be > 0, got {rate_hz!r}.')
        self.cfg = cfg
        self.recorder = recorder
        self.namespace = names.normalize_namespace(namespace)
        self.frame_id = frame_id
        self.rate_hz = rate_hz
        self.digit_source = digit_source
        self.sim = Simulation(cfg, digit_source)
        self.recording_error: str | None = None
        self._period_ns = round(1e9 / rate_hz)
        self._tick = 0  # the first reset is tick 1, so a request before it has a time >= 0
        self._step_id = 0  # last lockstep id sent
        self._reset_id = 0
        self._started = False
        self._channels: dict[str, int] = {}
        self.topics = {rel: names.resolve_topic(rel, NODE_NAME, self.namespace)
                       for rel in TOPICS}
        self.observation: np.ndarray | None = None
        self.episode_return = 0.0
        if recorder is not None:
            try:
                for rel, (typename, qos) in TOPICS.items():
                    self._channels[rel] = recorder.add_channel(self.topics[rel], typename, qos)
            except recording.RecordingError as e:
                self._recording_failed(e)

    # ------------------------------------------------------------------ env-like view
    @property
    def unwrapped(self) -> EpisodeRunner:
        return self

    @property
    def chamber(self) -> Chamber:
        return self.sim.chamber

    @property
    def n_actions(self) -> int:
        return len(SPOT_ACTIONS if self.cfg.uses_spotlight else BEAM_ACTIONS)

    # ------------------------------------------------------------------ driving
    def reset(self, seed: int | None = None, challenge: str | None = None,
              setting: str | None = None, *, request: bool = True) -> StepOutcome:
        """Start an episode, as the node does on a ResetRequest.

        Args:
            seed: Restart the random stream from this seed; None continues it.
            challenge: Switch to this challenge; None keeps the current one.
            setting: Switch to this setting; None keeps the current one.
            request: Record the ResetRequest as received on ``reset`` (the node's first,
                automatic episode has none).

        Returns:
            The reward of the initial state.
        """
        self._reset_id += 1
        t_recv = self._next_tick() - self._period_ns // 2
        if request:
            msg = types.new(types.RESET_REQUEST, header=convert.header(t_recv, self.frame_id),
                            reset_id=self._reset_id, has_seed=seed is not None,
                            seed=seed or 0, challenge=challenge or '', setting=setting or '')
            self._record('reset', msg, t_recv, t_recv)
        changes = {k: v for k, v in (('challenge', challenge), ('setting', setting)) if v}
        if changes and any(getattr(self.cfg, k) != v for k, v in changes.items()):
            # A new chamber keeps the random stream, so an unseeded reset stays reproducible.
            rng = self.sim.rng
            self.cfg = self.cfg.replace(**changes)
            self.sim = Simulation(self.cfg, self.digit_source)
            self.sim.rng = rng
        outcome = self.sim.reset(seed=seed)
        if not self._started:
            self._start(seed)
        t = self._tick * self._period_ns
        self._record('chamber/config', types.new(STRING, data=recording.config_json(
            self.cfg, seed, rate_hz=self.rate_hz, mode='lockstep')), t, t)
        self._publish_state(outcome, step_id=0, step=0, t=t)
        self.episode_return = 0.0
        return outcome

    def step(self, action: int) -> StepOutcome:
        """Send one discrete action as a lockstep LightCommand and advance one step.

        Args:
            action: Index into the challenge's discrete actions.

        Returns:
            The step's outcome.
        """
        self._step_id += 1
        t_recv = self._next_tick() - self._period_ns // 2
        msg = types.new(types.LIGHT_COMMAND, header=convert.header(t_recv, self.frame_id),
                        step_id=self._step_id, mode=convert.MODE_DISCRETE, action=int(action))
        return self.command(msg, t_recv)

    def command(self, msg: Any, t_recv: int | None = None) -> StepOutcome:
        """Apply a received LightCommand and step once (the node's lockstep callback).

        A command the light rejects is logged and the step runs with the light unchanged.

        Args:
            msg: The LightCommand as received.
            t_recv: When it was received [ns]; None = half a period before the next tick.

        Returns:
            The step's outcome.
        """
        if t_recv is None:
            t_recv = self._next_tick() - self._period_ns // 2
        self._record('light/command', msg, t_recv, convert.to_ns(msg.header.stamp))
        try:
            convert.apply_command(self.sim, msg)
        except ValueError as e:
            logger.warning('rejected light command: %s', e)
        outcome = self.sim.step()
        self._publish_state(outcome, step_id=int(msg.step_id), step=self.chamber.steps,
                            t=self._tick * self._period_ns)
        self.episode_return += outcome.reward
        return outcome

    def run_episode(self, policy: Policy, seed: int | None = None, *,
                    request: bool = True, challenge: str | None = None,
                    setting: str | None = None) -> tuple[float, int]:
        """Reset, then step with ``policy`` until the episode is truncated.

        Args:
            policy: ``(observation, runner) -> action``, e.g. ``OracleAgent().act``.
            seed: The episode seed (None continues the stream).
            request: Record a ResetRequest (see ``reset``).
            challenge: Switch challenge at this reset.
            setting: Switch setting at this reset.

        Returns:
            (undiscounted return of the steps, number of steps).
        """
        self.reset(seed, challenge, setting, request=request)
        steps = 0
        while True:
            outcome = self.step(policy(self.observation, self))
            steps += 1
            if outcome.truncated:
                return self.episode_return, steps

    # ------------------------------------------------------------------ internals
    def _next_tick(self) -> int:
        self._tick += 1
        return self._tick * self._period_ns

    def _start(self, seed: int | None) -> None:
        self._started = True
        if self.recorder is None or self.recording_error is not None:
            return
        try:
            self.recorder.add_metadata(recording.METADATA_NAME, recording.growspace_metadata(
                self.cfg, seed, namespace=self.namespace, frame_id=self.frame_id,
                rate_hz=self.rate_hz, lockstep=True, digit_source=self.digit_source,
                digit_fingerprint=recording.digit_fingerprint(self.sim)))
        except recording.RecordingError as e:
            self._recording_failed(e)

    def _publish_state(self, outcome: StepOutcome, *, step_id: int, step: int, t: int) -> None:
        self._record('/clock', convert.clock_msg(t), t, t)
        self.observation = self.sim.observe()
        self._record('camera/image_raw', convert.image_msg(self.observation, t, self.frame_id),
                     t, t)
        self._record('plant/state', convert.plant_state_msg(self.chamber, step_id, t,
                                                            self.frame_id), t, t)
        self._record('light/state', convert.light_msg(self.chamber.light, step_id, t,
                                                      self.frame_id), t, t)
        self._record('step_result', convert.step_result_msg(
            outcome, step_id=step_id, reset_id=self._reset_id, step=step, stamp_ns=t,
            frame_id=self.frame_id), t, t)

    def _record(self, rel: str, msg: Any, log_time: int, publish_time: int) -> None:
        cdr = types.serialize(msg, TOPICS[rel][0])  # what the node would publish
        if self.recorder is None or self.recording_error is not None:
            return
        try:
            self.recorder.write(self._channels[rel], cdr, log_time, publish_time)
        except recording.RecordingError as e:
            self._recording_failed(e)

    def _recording_failed(self, error: recording.RecordingError) -> None:
        # As in the node: the chamber keeps running, the user is told once.
        self.recording_error = str(error)
        logger.error('%s', error)
