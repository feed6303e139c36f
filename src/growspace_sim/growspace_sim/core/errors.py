"""The core's error for a command it cannot apply: a typed field, value and allowed range."""

from __future__ import annotations

from typing import Any


class CommandError(ValueError):
    """A light command or reset request that cannot be applied; the state is unchanged.

    Adapters key their throttled warnings on ``field`` and report ``str(error)``, so neither
    depends on the wording.

    Args:
        field: the command field, e.g. ``action``, ``continuous[1]``, ``x``, ``challenge``.
        value: the value it had.
        allowed: what is allowed, e.g. ``an int in [0, 4] (left, right, ...)``.
    """

    def __init__(self, field: str, value: Any, allowed: str) -> None:
        super().__init__(f'{field} = {value!r} is not allowed; expected {allowed}.')
        self.field = field
        self.value = value
        self.allowed = allowed
