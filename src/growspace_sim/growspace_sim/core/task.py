"""What makes a challenge: one ``Task`` object per challenge, and the registry that names them.

A challenge differs from another only in what a ``Task`` holds: where plants, target and light
start (``layout``), the light's kind, the observation size, the reward and success (``score``),
how many plants grow, its shape targets, its oracle and its Gymnasium ids. Everything else (SCA
growth, shading, light actions, rendering, the node) is shared. ``SimConfig.challenge`` names a
registered task, or ``module:attribute`` of a ``Task`` in a module of your own, loaded on first
use: adding a challenge is that one module (``docs/architecture.md`` has an example). The
built-in challenges live in ``core/tasks/``.

This module imports numpy only: a task is plain data and functions of numpy arrays. It is the
bottom of the core (``SimConfig`` names a task, the chamber calls it), so it imports no other
core module; the functions' argument types are named in their comments.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
import importlib
from typing import Any, Protocol

import numpy as np

from growspace_sim.core.errors import echo

SETTINGS = ('easy', 'hard')

Score = tuple[float, np.ndarray, bool]  # reward, (n_plants,) float64 per-plant reward, success


@dataclass(frozen=True)
class Layout:
    """The procedurally generated start of an episode, in metres."""

    stem_x: tuple[float, ...]  # m, one root per plant on the floor
    target: complex | None  # m, x + iz; None when the target is a shape (``Task.digits``)
    light_x: float  # m, initial light centre
    light_z: float = 0.0  # m, initial spotlight centre height (unused by a beam)


class Oracle(Protocol):
    """A privileged policy: reads the chamber, returns a discrete action index."""

    def act(self, chamber: Any) -> int:
        """The action for a ``core.chamber.Chamber`` in its current state."""


@dataclass(frozen=True, eq=False)  # a task is itself: compared and hashed by identity
class Task:
    """One challenge: what differs from the others. Build one per module and ``register`` it.

    Functions get the validated config and, where they draw, the episode's generator; they must
    draw in a fixed order so that an episode is a function of its seed.
    """

    name: str  # the value of SimConfig.challenge, e.g. 'find_plant'
    env_name: str  # the Gymnasium id part: GrowSpace/<env_name>[Continuous]-<Setting>-v0
    layout: Callable[..., Layout]  # (SimConfig, np.random.Generator) -> the episode's start
    score: Callable[..., Score]  # (ChamberState, SimConfig) -> the reward of a state
    spotlight: bool = False  # True: circular spotlight (x, z, radius); False: vertical beam
    resolution: int = 84  # px, the observation side when SimConfig.image_size is 0
    multi_plant: bool = False  # True: SimConfig.n_plants plants grow; False: one
    digits: Mapping[str, tuple[int, ...]] | None = None  # setting -> digits; None: point target
    oracle: Callable[[], Oracle] | None = None  # a fresh oracle (it may keep state)
    settings: tuple[str, ...] = SETTINGS
    # More Gymnasium ids: id -> (entry point, kwargs), e.g. the shape curriculum.
    extra_envs: Mapping[str, tuple[str, Mapping[str, Any]]] = field(default_factory=dict)


_REGISTRY: dict[str, Task] = {}
_LOADED: dict[str, Task] = {}  # 'module:attribute' -> the task it named (see ``get``)


def register(task: Task) -> Task:
    """Make a task available as ``SimConfig(challenge=task.name)``; returns it.

    Raises:
        ValueError: if another task already has this name or Gymnasium name.
    """
    for other in _REGISTRY.values():
        if other is task:
            return task
        if task.name == other.name or task.env_name == other.env_name:
            raise ValueError(f'task name {task.name!r} / env_name {task.env_name!r} is taken by '
                             f'{other.name!r}.')
    _REGISTRY[task.name] = task
    return task


def unregister(name: str) -> None:
    """Forget a task and the ``module:attribute`` names that loaded it (tests that define
    their own); unknown names are ignored."""
    task = _REGISTRY.pop(name, None)
    for key in [k for k, v in _LOADED.items() if v is task]:
        del _LOADED[key]


def get(name: str) -> Task:
    """The task called ``name``: a registered name, or ``module:attribute`` naming a ``Task``
    of your own, which is imported and registered the first time (as Gymnasium loads
    ``module:EnvId``), so a challenge needs its own module and nothing else.

    Raises:
        ValueError: naming the value and the registered names, or why the module or attribute
            could not be loaded.
    """
    task = _REGISTRY.get(name) or _LOADED.get(name)
    if task is not None:
        return task
    if isinstance(name, str) and ':' in name:
        return _load(name)
    raise ValueError(f'challenge must be one of {names()} or module:attribute naming a Task, '
                     f'got {echo(name)}.')


def _load(name: str) -> Task:
    module_name, _, attribute = name.partition(':')
    try:
        module = importlib.import_module(module_name)
    except ImportError as e:
        raise ValueError(f'challenge {name!r}: cannot import {module_name!r} ({e}).') from e
    task = getattr(module, attribute, None)
    if not isinstance(task, Task):
        raise ValueError(f'challenge {name!r}: {module_name}.{attribute} is '
                         f'{type(task).__name__}, not a growspace_sim.core.task.Task.')
    _LOADED[name] = register(task)
    return task


def known(name: str) -> bool:
    """Whether ``name`` is registered or was loaded already: what a message from the network
    may name (loading ``module:attribute`` imports code, which only the node's operator may
    ask for, at start-up)."""
    return name in _REGISTRY or name in _LOADED


def names() -> tuple[str, ...]:
    """The registered challenge names, in registration order."""
    return tuple(_REGISTRY)


def all_tasks() -> tuple[Task, ...]:
    """The registered tasks, in registration order."""
    return tuple(_REGISTRY.values())
