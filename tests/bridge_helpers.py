"""Shared pieces of the bridge tests: the session's ROS domain and exact comparisons."""

from __future__ import annotations

from collections.abc import Iterator
import os
from typing import Any

import numpy as np


def loopback_domain() -> Iterator[int]:
    """The test module's ROS domain (conftest: loopback only, one per module), for fixtures."""
    yield int(os.environ['ROS_DOMAIN_ID'])


def assert_identical(a: Any, b: Any, where: str = 'value') -> None:
    """Exact equality of nested dicts, tuples and arrays (same dtype, shape and bytes)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a) == sorted(b), f'{where}: {sorted(a)} vs {b}'
        for key in a:
            assert_identical(a[key], b[key], f'{where}[{key!r}]')
    elif isinstance(a, (tuple, list)):
        assert type(a) is type(b) and len(a) == len(b), f'{where}: {a!r} vs {b!r}'
        for i, (x, y) in enumerate(zip(a, b)):
            assert_identical(x, y, f'{where}[{i}]')
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray), f'{where}: array vs {type(b)}'
        assert a.dtype == b.dtype and a.shape == b.shape, \
            f'{where}: {a.dtype}{a.shape} vs {b.dtype}{b.shape}'
        if a.dtype == object:  # vector envs gather per-env tuples and dicts this way
            for i, (x, y) in enumerate(zip(a.reshape(-1), b.reshape(-1))):
                assert_identical(x, y, f'{where}[{i}]')
        else:
            assert a.tobytes() == b.tobytes(), f'{where}: values differ'
    else:
        assert a == b and np.asarray(a).dtype.kind == np.asarray(b).dtype.kind, \
            f'{where}: {a!r} ({type(a).__name__}) vs {b!r} ({type(b).__name__})'


def assert_same_transition(bridged: tuple, local: tuple, where: str) -> None:
    """Two (obs, info) resets or (obs, reward, terminated, truncated, info) steps are identical."""
    names = ('obs', 'info') if len(bridged) == 2 else ('obs', 'reward', 'terminated',
                                                       'truncated', 'info')
    for name, x, y in zip(names, bridged, local):
        assert_identical(x, y, f'{where} {name}')
