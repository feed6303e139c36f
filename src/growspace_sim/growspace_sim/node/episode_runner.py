"""Drive ``sim_node``'s ``ChamberNode`` in process with an agent, optionally recording it.

The runner is a lockstep client of a real ``ChamberNode`` on an in-memory transport
(``node.local.LocalTransport``): it sends ResetRequests and LightCommands as a client would, and
the node handles, publishes and records them exactly as it does on rclpy. So a recording
made here and one made by ``sim_node --ros-args -p record_path:=...`` have the same channels,
message order, stamps and metadata, and re-simulate the same way; the sample bags, the recording
tests and the benchmark use it. The message order and stamps are the node's (``ros.interface``
and ``docs/recording.md``).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np

from growspace_sim.core.chamber import Chamber
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import BEAM_ACTIONS, SPOT_ACTIONS
from growspace_sim.node.chamber_node import ChamberNode, Recorder
from growspace_sim.node.local import LocalTransport
from growspace_sim.node.resume import ResumePoint
from growspace_sim.node.params import DEFAULT_NODE_NAME, NodeParams
from growspace_sim.ros import convert, types
from growspace_sim.ros.names import DEFAULT_NAMESPACE



class EpisodeRunner:
    """A lockstep client of an in-process ``ChamberNode``.

    The node starts at the first ``reset`` (its automatic first episode, with that seed, as
    ``sim_node -p seed:=...`` does); every later ``reset`` is a ResetRequest. It has Gymnasium's
    ``reset``/``step`` and enough of an env (``unwrapped``, ``chamber``, ``continuous``) for
    ``agents.play_episodes`` to play it with any agent, the oracle included.

    Args:
        cfg: The configuration of the first episode.
        recorder: Gets every message the node handles; None records nothing (the node still
            builds and serialises every message: the baseline of the recording benchmark).
        namespace: Chamber namespace the topics are resolved in.
        frame_id: ``header.frame_id`` of the plant state, light state and step results.
        rate_hz: Steps per second of simulated time.
        digit_source: Shape targets' source (``digits.load_digits``).

    Raises:
        ValueError: A node parameter is invalid (e.g. ``rate_hz``).
    """

    continuous = False

    def __init__(self, cfg: SimConfig, recorder: Recorder | None = None, *,
                 namespace: str = DEFAULT_NAMESPACE, frame_id: str = 'chamber',
                 rate_hz: float = 10.0, digit_source: str = 'auto') -> None:
        self.cfg = cfg
        self.recorder = recorder
        self.params = NodeParams(rate_hz=rate_hz, frame_id=frame_id)
        self.digit_source = digit_source
        self.transport = LocalTransport(DEFAULT_NODE_NAME, namespace)
        self.node: ChamberNode | None = None
        self.observation: np.ndarray | None = None
        self.result: Any = None  # the latest StepResult
        self._step_id = 0
        self._reset_id = 0
        self._image_topic = self.transport.resolve('camera/image_raw')
        self._result_topic = self.transport.resolve('step_result')

    # ------------------------------------------------------------------ env-like view
    @property
    def unwrapped(self) -> EpisodeRunner:
        return self

    @property
    def chamber(self) -> Chamber:
        return self._node.sim.chamber

    @property
    def n_actions(self) -> int:
        cfg = self.cfg if self.node is None else self.node.cfg
        return len(SPOT_ACTIONS if cfg.uses_spotlight else BEAM_ACTIONS)

    @property
    def action_space(self) -> gym.spaces.Discrete:
        """The challenge's discrete actions (the runner sends discrete LightCommands)."""
        return gym.spaces.Discrete(self.n_actions)

    @property
    def recording_error(self) -> str | None:
        """Why the node stopped recording, or None."""
        return None if self.node is None else self.node.recording_error

    @property
    def _node(self) -> ChamberNode:
        if self.node is None:
            raise RuntimeError('call reset() first: the node starts at the first reset.')
        return self.node

    # ------------------------------------------------------------------ driving
    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: the node's first one, then by ResetRequest (Gymnasium's API).

        Args:
            seed: Restart the random stream from this seed; None continues it (for the node's
                first episode: a random seed, which the recording keeps).
            options: ``challenge`` and ``setting`` to switch to (absent: keep the current).

        Returns:
            The observation and info (``step``, ``success``, ``plant_rewards``) of the start.

        Raises:
            ValueError: The node rejected the reset (the message says why), or an unknown
                option.
        """
        options = dict(options or {})
        unknown = sorted(set(options) - {'challenge', 'setting'})
        if unknown:
            raise ValueError(f'reset options {unknown} are unknown; allowed: challenge, setting.')
        challenge, setting = options.get('challenge'), options.get('setting')
        if self.node is None:
            changes = {k: v for k, v in (('challenge', challenge), ('setting', setting)) if v}
            params = dataclasses.replace(self.params, seed=-1 if seed is None else seed)
            self.node = ChamberNode(self.transport, self.cfg.replace(**changes), params,
                                    self.recorder, self.digit_source)
            self._answered()
        else:
            self._reset_id += 1
            self._send('reset', types.new(
                types.RESET_REQUEST, header=self._header(), reset_id=self._reset_id,
                has_seed=seed is not None, seed=seed or 0, challenge=challenge or '',
                setting=setting or ''))
        self._step_id = 0
        return self.observation, self._info()

    def resume(self, point: ResumePoint) -> np.ndarray:
        """Start the node where a recording ends (``replay.resume_point``), not with a reset.

        The next ``step`` sends the step_id after the recorded last one, in the recorded
        episode, as a client that never stopped would.

        Returns:
            The observation after the recorded last step (re-simulated).

        Raises:
            RuntimeError: The node runs already.
        """
        if self.node is not None:
            raise RuntimeError('resume() starts the node; it runs already.')
        self.node = ChamberNode(self.transport, self.cfg, self.params, self.recorder,
                                self.digit_source, resume=point)
        self._reset_id, self._step_id = point.reset_id, point.last_step_id
        self.observation = point.sim.observe()
        return self.observation

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Send one discrete action as a lockstep LightCommand; the node steps once.

        Args:
            action: Index into the challenge's discrete actions.

        Returns:
            Gymnasium's (observation, reward, terminated, truncated, info), from the node's
            messages.

        Raises:
            ValueError: The node rejected the command without stepping (the message says why).
        """
        self._step_id += 1
        self._send('light/command', convert.discrete_command_msg(
            int(action), self._step_id, self._stamp_ns(), self._node.params.frame_id))
        result = self.result
        return self.observation, float(result.reward), bool(result.terminated), \
            bool(result.truncated), self._info()

    def close(self) -> None:
        """Close the node, which finishes the recording. Idempotent."""
        if self.node is not None:
            self.node.close()

    # ------------------------------------------------------------------ internals
    def _header(self) -> Any:
        return convert.header(self._stamp_ns(), self._node.params.frame_id)

    def _stamp_ns(self) -> int:
        # A request is stamped when the node will receive it: half a period after its tick.
        node = self._node
        return node.sim_time_ns + node.params.period_ns // 2

    def _send(self, topic: str, msg: Any) -> None:
        """Deliver a request to the node and take its answer (the StepResult it published)."""
        previous = self.transport.latest.get(self._result_topic)  # none yet after resume()
        self.transport.inject(topic, msg)
        result = self.transport.latest[self._result_topic]
        if result is previous or result.info:
            # Rejected (the node answered without stepping or resetting, saying why).
            raise ValueError(f'{topic}: {result.info if result is not previous else "no answer"}')
        self._answered()

    def _info(self) -> dict[str, Any]:
        result = self.result
        return {'step': int(result.step), 'success': bool(result.success),
                'plant_rewards': np.asarray(result.plant_rewards, np.float64)}

    def _answered(self) -> None:
        self.result = self.transport.latest[self._result_topic]
        self.observation = convert.image_from_msg(self.transport.latest[self._image_topic])
