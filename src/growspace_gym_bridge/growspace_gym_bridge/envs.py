"""A Gymnasium env that plays a GrowSpace chamber through its ROS 2 topics (lockstep)."""

from __future__ import annotations

from collections.abc import Callable
import itertools
import os
import secrets
import time
from typing import Any

import gymnasium as gym
from gymnasium.utils import EzPickle
import numpy as np

from growspace_sim.core.config import SimConfig
from growspace_sim.envs.env import as_action_index, check_env_args, spaces_for
from growspace_sim.node import params as node_params_mod
from growspace_sim.node.chamber_node import EPISODE_OVER
from growspace_sim.ros import convert
from growspace_sim.ros import loopback

from growspace_gym_bridge.errors import BridgeError, CommandRejected, NodeDied
from growspace_gym_bridge.link import ChamberLink, Reply
from growspace_gym_bridge.process import NodeProcess

STEP_TIMEOUT_S = 10.0  # per reset or step; generous for a loaded machine [s]
CONNECT_TIMEOUT_S = 60.0  # node start-up (imports, typestore) plus discovery [s]
PRESENCE_CHECK_S = 0.5  # how often an attached node's presence is checked while waiting [s]
_COUNTER = itertools.count(1)

# A DDS participant does not survive fork(): a child that uses the copy can hang. Count ours,
# so a forked child can be told to use 'spawn' instead of hanging.
_live_transports = 0
_forked_with_live_dds = False


def _after_fork_in_child() -> None:
    global _forked_with_live_dds
    _forked_with_live_dds = _forked_with_live_dds or _live_transports > 0


os.register_at_fork(after_in_child=_after_fork_in_child)


def _as_index(action: Any) -> int:
    action = as_action_index(action)
    if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
        raise CommandRejected(f'a discrete action must be an integer, got {action!r}.')
    return int(action)


class GrowSpaceBridgeEnv(gym.Env, EzPickle):
    """The GrowSpace challenges played through a lockstep ``sim_node`` over ROS 2 topics.

    ## Description
    The same task as ``growspace_sim.envs.env.GrowSpaceEnv`` (same spaces, rewards, infos and,
    for the same seed and actions, bit-identical observations), but the chamber runs in a
    ``sim_node`` process: ``reset`` publishes a ``ResetRequest`` on ``reset``, ``step``
    publishes a ``LightCommand`` on ``light/command`` with a step id, and both wait for the
    ``step_result`` with their ids plus the ``camera/image_raw``, ``plant/state`` and
    ``light/state`` messages of the same step (same header stamp). Late or duplicate replies
    are dropped by id. Without ``namespace`` the env starts its own node (a child process in a
    unique namespace, confined to loopback like everything we start) and stops it on
    ``close``; with one it attaches to a running lockstep node (one client per node: another
    client's resets would move the chamber). The env talks through its own rclpy context and
    executor, so it leaves an application's rclpy state and signal handlers alone.

    ## Action Space
    As the in-process env: ``Discrete(5)`` for the beam challenges (left, right, stay, wider,
    narrower), ``Discrete(7)`` for ``shape`` (left, right, up, down, bigger, smaller, stay);
    with ``continuous=True`` ``Box(-1, 1, (2,), float32)`` (velocity [light steps], width)
    or ``Box(-1, 1, (3,), float32)`` (dx, dz [light steps], radius). Continuous actions travel
    as float32, the space's dtype.

    ## Observation Space
    ``Box(0, 255, (84, 84, 3), uint8)`` RGB (28 x 28 for ``shape``), the ``rgb8`` image the node
    publishes; with ``observation='features'`` the binary planes ``image > 0``.

    ## Rewards
    ``StepResult.reward``: the in-process reward [1] (control, find_plant: ``max 1/d`` to the
    target in target radii; fairness: minimum over plants; shape: Jaccard index).

    ## Starting State
    As the in-process env: ``reset(seed=s)`` seeds the node's generator with ``s``;
    ``reset()`` continues its stream.

    ## Episode End
    Truncation after ``episode_length`` (50) steps; there is no terminal state. Stepping a
    finished episode raises ``gymnasium.error.ResetNeeded``.

    ## Arguments
    | argument | meaning |
    |---|---|
    | ``challenge``, ``setting`` | task; None: control/easy (own node) or the node's (attached) |
    | ``continuous``, ``observation``, ``render_mode`` | as the in-process env |
    | ``namespace`` | chamber namespace to attach to; None starts an own node |
    | ``start_node`` | start a node in ``namespace`` (default: only when it is None) |
    | ``domain_id`` | ROS_DOMAIN_ID (default: the environment's) |
    | ``with_state`` | read plant and light state for ``info`` (False: faster, smaller info) |
    | ``timeout_s`` | limit of every reset and step wait [s] |
    | ``connect_timeout_s`` | limit for the node to start and match [s] |
    | ``node_params`` | extra node parameters for an own node, e.g. ``record_path`` |
    | ``config``, ``**overrides`` | ``SimConfig`` and field overrides, as the in-process env |

    ## Info
    As the in-process env: ``step``, ``tips`` (per plant (K, 2) tip positions [m]),
    ``branch_counts``, ``plant_rewards``, ``light`` (x, z, width, radius [m]), ``success`` and,
    for shape, ``digit``. With ``with_state=False``: no ``tips``, ``branch_counts``, ``light``.

    ## Errors
    ``BridgeTimeout`` (a ``TimeoutError``) names the topic, step id and timeout; ``NodeDied``
    the node's exit code and last stderr lines; ``CommandRejected`` (a ``ValueError``) the
    node's reason for refusing a command or reset. Each survives pickling with its text and
    fields, so ``AsyncVectorEnv`` hands the parent the error its worker saw. A node the env
    starts stops by itself once the process that started it is gone.
    """

    metadata = {'render_modes': ['rgb_array'], 'render_fps': 10}

    def __init__(self, challenge: str | None = None, setting: str | None = None, *,
                 continuous: bool = False, observation: str = 'rgb',
                 render_mode: str | None = None, namespace: str | None = None,
                 start_node: bool | None = None, domain_id: int | None = None,
                 with_state: bool = True, timeout_s: float = STEP_TIMEOUT_S,
                 connect_timeout_s: float = CONNECT_TIMEOUT_S,
                 node_params: dict[str, Any] | None = None, config: SimConfig | None = None,
                 **overrides: Any) -> None:
        EzPickle.__init__(self, challenge, setting, continuous=continuous,
                          observation=observation, render_mode=render_mode, namespace=namespace,
                          start_node=start_node, domain_id=domain_id, with_state=with_state,
                          timeout_s=timeout_s, connect_timeout_s=connect_timeout_s,
                          node_params=node_params, config=config, **overrides)
        check_env_args(observation, render_mode)
        if not timeout_s > 0 or not connect_timeout_s > 0:
            raise ValueError(f'timeouts must be > 0 s, got {timeout_s!r} and '
                             f'{connect_timeout_s!r}.')
        self.continuous = continuous
        self.observation = observation
        self.render_mode = render_mode
        self.with_state = with_state
        self.timeout_s = float(timeout_s)
        self.connect_timeout_s = float(connect_timeout_s)
        self.domain_id = domain_id
        self.node: NodeProcess | None = None
        self.link: ChamberLink | None = None
        self._transport: Any = None
        self._closed = False
        self._reset_id = secrets.randbits(40) << 16  # unique per client; +1 per reset
        self._episode_reset_id: int | None = None
        self._step_id = 0
        self._digit: int | None = None  # shape: the digit of this episode
        self._last_rgb: np.ndarray | None = None
        self._next_presence_check = 0.0
        start = namespace is None if start_node is None else start_node
        self.namespace = namespace or (f'/growspace_bridge_{os.getpid()}_{next(_COUNTER)}_'
                                       f'{secrets.token_hex(3)}')
        values = self._param_values(challenge, setting, config, overrides)
        if start:
            cfg, _ = node_params_mod.build({**values, **(node_params or {}),
                                            'mode': 'lockstep'})  # ParamError names the field
            self.cfg = cfg
            self.node = NodeProcess(self.namespace, {**values, **(node_params or {}),
                                                     'mode': 'lockstep'},
                                    domain_id=domain_id)
        else:
            if node_params:
                raise ValueError('node_params only apply to a node the env starts, got '
                                 f'{sorted(node_params)} for the running node {namespace}.')
            self.cfg = self._attach(challenge, setting, values)
        self.action_space, self.observation_space = spaces_for(self.cfg, continuous,
                                                               observation)

    @property
    def node_pid(self) -> int | None:
        """Process id of the node this env started (None when attached)."""
        return None if self.node is None else self.node.pid

    # --- setup ---------------------------------------------------------------------------

    @staticmethod
    def _param_values(challenge: str | None, setting: str | None, config: SimConfig | None,
                      overrides: dict[str, Any]) -> dict[str, Any]:
        """Node parameter values that differ from the defaults (a short command line)."""
        base = config or SimConfig()
        wanted = {k: v for k, v in (('challenge', challenge), ('setting', setting)) if v}
        cfg = base.replace(**{**overrides, **wanted}) if (overrides or wanted) else base
        default = SimConfig()
        # as_values gives tuples as lists, the form ROS parameters carry.
        return {name: value for name, value in node_params_mod.as_values(
            cfg, node_params_mod.NodeParams()).items()
            if hasattr(default, name) and getattr(default, name) != getattr(cfg, name)}

    def _attach(self, challenge: str | None, setting: str | None,
                values: dict[str, Any]) -> SimConfig:
        config = self._connect()
        node_cfg, node_settings = node_params_mod.build(config['config'])
        if node_settings.mode != 'lockstep':
            self.close()
            raise BridgeError(f'sim node {self.namespace} runs in {node_settings.mode} mode; '
                              f'the bridge needs mode:=lockstep.')
        changes = {k: v for k, v in (('challenge', challenge), ('setting', setting)) if v}
        cfg = node_cfg.replace(**changes) if changes else node_cfg
        for name, value in values.items():
            if name not in changes and getattr(cfg, name) != (tuple(value) if isinstance(
                    value, list) else value):
                self.close()
                raise ValueError(f'{name} = {value!r} differs from the running node '
                                 f'{self.namespace} ({getattr(cfg, name)!r}); parameters of a '
                                 f'running node cannot be changed over topics.')
        return cfg

    def _connect(self) -> dict[str, Any]:
        """Create our endpoints and wait for the node; returns its chamber/config."""
        global _live_transports
        if self._closed:
            raise BridgeError(f'the bridge env of {self.namespace} is closed.')
        if self.link is not None:
            return self.link.config or {}
        if _forked_with_live_dds:
            raise BridgeError('this process was forked while a bridge env held a ROS 2 '
                              'context, which DDS does not survive; create '
                              "AsyncVectorEnv(..., context='spawn') or 'forkserver'.")
        self._transport = self._make_transport()
        _live_transports += 1
        self.link = ChamberLink(self._transport, self.with_state, self._check_alive)
        return self.link.connect(self.connect_timeout_s)

    def _make_transport(self) -> Any:
        from growspace_sim.node.rclpy_transport import RclpyTransport

        if self.node is not None:  # our own node: our side stays on loopback as well
            loopback.confine()
        name = f'gym_bridge_{os.getpid()}_{secrets.token_hex(4)}'
        return RclpyTransport(name, self.namespace, domain_id=self.domain_id)

    def _check_alive(self, describe: Callable[[], str]) -> None:
        if self.node is not None:
            code = self.node.poll()
            if code is not None:
                raise NodeDied(self.namespace, code, self.node.stderr_tail(), describe())
        elif time.monotonic() >= self._next_presence_check and self.link is not None \
                and self.link.config is not None:
            self._next_presence_check = time.monotonic() + PRESENCE_CHECK_S
            if not self.link.node_present():
                raise NodeDied(self.namespace, None, (), describe())

    # --- Gymnasium API -------------------------------------------------------------------

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self._connect()
        self._reset_id += 1
        self._episode_reset_id, self._step_id = None, 0
        reply = self.link.reset(self._reset_id, seed, self.cfg.challenge, self.cfg.setting,
                                self.timeout_s, with_config=self.cfg.task.digits is not None)
        if reply.result.info:
            raise CommandRejected(f'{self.link.transport.resolve("reset")}: reset_id '
                                  f'{self._reset_id} refused: {reply.result.info}')
        self._episode_reset_id = self._reset_id
        if reply.config is not None:  # shape: the node says which digit it drew
            self._digit = int(reply.config['digit'])
        return self._observe(reply), self._info(reply)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self._episode_reset_id is None:
            raise gym.error.ResetNeeded('call reset() before step() (bridge env '
                                        f'{self.namespace}).')
        self._step_id += 1
        if self.continuous:
            reply = self.link.step(self._episode_reset_id, self._step_id, self.timeout_s,
                                   continuous=action)
        else:
            reply = self.link.step(self._episode_reset_id, self._step_id, self.timeout_s,
                                   action=_as_index(action))
        result = reply.result
        if result.info == EPISODE_OVER:
            raise gym.error.ResetNeeded(f'{self.namespace}: step_id {self._step_id}: the '
                                        f'episode is over; call reset().')
        if result.info:
            raise CommandRejected(f'{self.link.transport.resolve("light/command")}: step_id '
                                  f'{self._step_id} refused: {result.info}')
        return (self._observe(reply), float(result.reward), bool(result.terminated),
                bool(result.truncated), self._info(reply))

    def render(self) -> np.ndarray | None:
        if self.render_mode == 'rgb_array' and self._last_rgb is not None:
            return self._last_rgb.copy()
        return None

    def close(self) -> None:
        """Release our endpoints and stop the node we started (SIGTERM, then SIGKILL)."""
        global _live_transports
        if self._closed:
            return
        self._closed = True
        transport, self._transport, self.link = self._transport, None, None
        if transport is not None:
            _live_transports -= 1
            try:
                transport.close()
            except Exception:  # noqa: BLE001 - stopping the node matters more
                pass
        if self.node is not None:
            self.node.stop()
        super().close()

    # --- replies -> Gymnasium ------------------------------------------------------------

    def _observe(self, reply: Reply) -> np.ndarray:
        rgb = np.array(convert.image_from_msg(reply.image), copy=True)
        if rgb.shape != self.observation_space.shape:
            raise BridgeError(f'{self.link.transport.resolve("camera/image_raw")}: image '
                              f'{rgb.shape} does not fit the observation space '
                              f'{self.observation_space.shape}; is the node configured alike?')
        self._last_rgb = rgb
        if self.observation == 'features':
            return (rgb > 0).view(np.uint8)  # as Renderer.features
        return rgb.copy() if self.render_mode else rgb

    def _info(self, reply: Reply) -> dict[str, Any]:
        result = reply.result
        info: dict[str, Any] = {'step': int(result.step)}
        if self.with_state:
            plant = reply.plant
            tips = np.asarray(plant.tips, np.intp)
            xz = np.column_stack((plant.node_x[tips], plant.node_z[tips]))
            if self.cfg.plant_count == 1:
                info['tips'] = (xz,)
            else:
                owner = plant.plant[tips]
                info['tips'] = tuple(xz[owner == p] for p in range(self.cfg.plant_count))
            info['branch_counts'] = np.asarray(plant.branch_count, np.int64)
        info['plant_rewards'] = np.array(result.plant_rewards, np.float64)
        if self.with_state:
            info['light'] = {'x': reply.light.x, 'z': reply.light.z, 'width': reply.light.width,
                             'radius': reply.light.radius}
        info['success'] = bool(result.success)
        if self.cfg.task.digits is not None:
            info['digit'] = self._digit
        return info
