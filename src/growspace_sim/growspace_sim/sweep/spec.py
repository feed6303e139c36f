"""Sweep specs: the YAML file or flags, validated into trials (agents x env ids x seeds)."""

from __future__ import annotations

import argparse
from collections.abc import Mapping
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import yaml

from growspace_sim import learn
from growspace_sim.agents import evaluation
from growspace_sim.core.schema import Bounds


BASELINES = evaluation.AGENTS
LEARNERS = ('ppo', 'a2c', 'dqn', 'rainbow')  # growspace_sim.learn.train.ALGOS, without torch
SPEC_KEYS = ('name', 'episodes', 'eval_seed', 'runs')
GROUP_KEYS = ('agents', 'envs', 'seeds', 'steps', 'hp', 'n_envs', 'max_minutes', 'device',
              'env_kwargs', 'label')
LEARNER_KEYS = ('steps', 'hp', 'n_envs', 'max_minutes', 'device')


class SpecError(ValueError):
    """A sweep spec with a missing, unknown or invalid field."""


@dataclass(frozen=True)
class Trial:
    """One agent on one env id with one seed: the unit Ray Tune schedules."""

    agent: str                  # random, oracle, ppo, a2c, dqn or rainbow
    env: str                    # the training (or playing) env id
    seed: int                   # training seed; the random agent's action seed is eval_seed + seed
    episodes: int               # evaluation episodes
    eval_seed: int              # first evaluation episode seed
    steps: int = 0              # training steps (learners)
    label: str = ''             # the table's agent column; '' = the agent (or run) name
    hp: dict = field(default_factory=dict)
    env_kwargs: dict = field(default_factory=dict)
    n_envs: int | None = None
    max_minutes: float | None = None
    device: str = 'cpu'

    @property
    def key(self) -> str:
        """A readable, unique file name, e.g. ``ppo-control-hard-s2``."""
        name = self.env.split('/')[-1].rsplit('-', 1)[0].lower()
        return re.sub(r'[^a-z0-9_.-]+', '_', f'{self.label or self.agent}-{name}-s{self.seed}'
                      .lower())


@dataclass(frozen=True)
class Spec:
    """A validated experiment: its name, evaluation episodes and trials."""

    name: str
    episodes: int
    eval_seed: int
    trials: tuple[Trial, ...]


def load_spec(path: str | os.PathLike) -> Spec:
    """Read and validate a YAML spec file.

    Raises:
        SpecError: naming the field, the value and what is allowed.
    """
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as error:
        raise SpecError(f'Cannot read the spec {path}: {error}') from error
    return parse_spec(data, default_name=Path(path).stem)


def parse_spec(data: Any, default_name: str = 'sweep') -> Spec:
    """Validate a spec mapping (see the module docstring) and expand its trials.

    Raises:
        SpecError: naming the field, the value and what is allowed.
    """
    if not isinstance(data, Mapping):
        raise SpecError(f'A spec is a mapping with keys {", ".join(SPEC_KEYS)}; '
                        f'got {type(data).__name__}.')
    _check_keys(data, SPEC_KEYS, 'spec')
    name = data.get('name', default_name)
    if not isinstance(name, str) or not re.fullmatch(r'[A-Za-z0-9_.-]+', name):
        raise SpecError(f'name must be letters, digits, "_", "." or "-"; got {name!r}.')
    episodes = _integer(data.get('episodes', 50), 'episodes', minimum=2)
    eval_seed = _integer(data.get('eval_seed', 10_000), 'eval_seed', minimum=0)
    groups = data.get('runs')
    if not isinstance(groups, list) or not groups:
        raise SpecError(f'runs must be a non-empty list of groups; got {groups!r}.')
    trials: dict[str, tuple[Trial, str]] = {}
    for index, group in enumerate(groups):
        where = f'runs[{index}]'
        for trial in _expand(group, where, episodes, eval_seed):
            if trial.key in trials:
                other = trials[trial.key][1]
                raise SpecError(f'{where}: trial {trial.key} is also in {other}; give one '
                                'group a distinct label.')
            trials[trial.key] = (trial, where)
    return Spec(name, episodes, eval_seed, tuple(t for t, _ in trials.values()))


def flags_spec(args: argparse.Namespace) -> Spec:
    """A one-group spec from ``--agents --envs --seeds --steps --episodes --eval-seed``."""
    group: dict[str, Any] = {'agents': args.agents.split(','), 'envs': args.envs.split(','),
                             'seeds': _seeds_flag(args.seeds)}
    if args.steps is not None:
        group['steps'] = args.steps
    return parse_spec({'name': args.name or 'sweep', 'episodes': args.episodes,
                       'eval_seed': args.eval_seed, 'runs': [group]})


def _seeds_flag(text: str) -> int | list[int]:
    try:
        return int(text) if ',' not in text else [int(s) for s in text.split(',')]
    except ValueError as error:
        raise SpecError(f'--seeds takes a count or a comma-separated list; got {text!r}.') \
            from error


def _expand(group: Any, where: str, episodes: int, eval_seed: int) -> list[Trial]:
    if not isinstance(group, Mapping):
        raise SpecError(f'{where} must be a mapping with keys {", ".join(GROUP_KEYS)}; '
                        f'got {group!r}.')
    _check_keys(group, GROUP_KEYS, where)
    agents = _names(group.get('agents'), f'{where}.agents', BASELINES + LEARNERS)
    envs = _names(group.get('envs'), f'{where}.envs', _env_ids())
    seeds = group.get('seeds', 1)
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        seeds = list(range(_integer(seeds, f'{where}.seeds', minimum=1)))
    elif isinstance(seeds, list) and seeds:
        seeds = [_integer(s, f'{where}.seeds[{i}]', minimum=0) for i, s in enumerate(seeds)]
    else:
        raise SpecError(f'{where}.seeds must be a count >= 1 or a non-empty list of seeds; '
                        f'got {seeds!r}.')
    learners = [a for a in agents if a in LEARNERS]
    if not learners:
        extra = sorted(set(group) & set(LEARNER_KEYS))
        if extra:
            raise SpecError(f'{where}: {", ".join(extra)} only apply to learners '
                            f'({", ".join(LEARNERS)}); the group has {agents}.')
    options: dict[str, Any] = {
        'label': _text(group.get('label', ''), f'{where}.label'),
        'env_kwargs': _mapping(group.get('env_kwargs', {}), f'{where}.env_kwargs')}
    if learners:
        if 'steps' not in group:
            raise SpecError(f'{where}: steps is required for {", ".join(learners)}.')
        if learn.missing():
            raise SpecError(f'{where}: agents {learners} need the learn extra '
                            '(pip install -r requirements-learn.txt).')
        options.update(steps=_integer(group['steps'], f'{where}.steps', minimum=1),
                       hp=_mapping(group.get('hp', {}), f'{where}.hp'),
                       device=_text(group.get('device', 'cpu'), f'{where}.device'))
        if 'n_envs' in group:
            options['n_envs'] = _integer(group['n_envs'], f'{where}.n_envs', minimum=1)
        if 'max_minutes' in group:
            options['max_minutes'] = _positive(group['max_minutes'], f'{where}.max_minutes')
    trials = []
    for agent in agents:
        for env in envs:
            if agent == 'oracle' and gym.spec(env).kwargs.get('continuous'):
                raise SpecError(f'{where}: the oracle acts through discrete actions; '
                                f'{env} is continuous.')
            for seed in seeds[:1] if agent == 'oracle' else seeds:
                kwargs = options if agent in LEARNERS else {
                    k: v for k, v in options.items() if k not in LEARNER_KEYS}
                trials.append(Trial(agent, env, seed, episodes, eval_seed, **kwargs))
    return trials


def _env_ids() -> tuple[str, ...]:
    return tuple(sorted(k for k in gym.registry if k.startswith('GrowSpace/')))


def _check_keys(data: Mapping, allowed: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(map(str, data)) - set(allowed))
    if unknown:
        raise SpecError(f'{where}: unknown key(s) {", ".join(unknown)}; '
                        f'allowed: {", ".join(allowed)}.')


def _names(value: Any, where: str, allowed: tuple[str, ...]) -> list[str]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value:
        raise SpecError(f'{where} must be a non-empty list; got {value!r}.')
    for item in value:
        if item not in allowed:
            raise SpecError(f'{where}: unknown {item!r}; allowed: {", ".join(allowed)}.')
    if len(set(value)) != len(value):
        raise SpecError(f'{where} lists a name twice: {value}.')
    return list(value)


def _integer(value: Any, where: str, minimum: int) -> int:
    return _within(Bounds(minimum, integer=True), where, value)


def _positive(value: Any, where: str) -> float:
    return float(_within(Bounds(0.0, low_open=True), where, value))


def _within(bounds: Bounds, where: str, value: Any) -> Any:
    try:
        bounds.check(where, value)
    except ValueError as error:
        raise SpecError(str(error)) from None
    return value


def _mapping(value: Any, where: str) -> dict:
    if not isinstance(value, Mapping):
        raise SpecError(f'{where} must be a mapping; got {value!r}.')
    return dict(value)


def _text(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise SpecError(f'{where} must be a string; got {value!r}.')
    return value
