"""The core's error for a command it cannot apply: a typed field, value and allowed range.

Also the base of every error that carries typed fields (``StructuredError``): such an error
must cross a process boundary intact, because Gymnasium's ``AsyncVectorEnv`` pickles a
worker's exception to the parent and raises ``type(error)(error)`` there.
"""

from __future__ import annotations

import copy
from typing import Any

ECHO_CHARS = 200  # longest repr of a bad value an error message quotes [characters]


def _rebuild(cls: type, args: tuple, fields: dict[str, Any]) -> BaseException:
    """Unpickle a ``StructuredError``: its message and fields as they were, no ``__init__``."""
    error = cls.__new__(cls)
    error.args = args
    error.__dict__.update(fields)
    return error


class _CopiedWhenCalledWithItself(type):
    """``Error(error)`` returns a copy of ``error``: what Gymnasium's vector env does with a
    worker's exception in the parent, where ``__init__``'s own arguments would not fit."""

    def __call__(cls, *args: Any, **kwargs: Any) -> Any:
        if len(args) == 1 and not kwargs and type(args[0]) is cls:
            return copy.copy(args[0])
        return super().__call__(*args, **kwargs)


class StructuredError(Exception, metaclass=_CopiedWhenCalledWithItself):
    """An error built from typed fields rather than a message, that survives ``pickle`` and
    ``copy`` with the same text and fields (the default rebuilds an exception by calling
    ``__init__`` with its message alone, which fails once ``__init__`` wants fields)."""

    def __reduce__(self) -> tuple:
        return _rebuild, (type(self), self.args, dict(self.__dict__))


def echo(value: Any, limit: int = ECHO_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters, saying how long it was, so that an error
    about a huge input (a 100,000-element array) stays one readable line.

    Args:
        value: the offending value.
        limit: the longest text returned [characters].

    Returns:
        The repr, or its start followed by ``... (N characters)``.
    """
    text = repr(value)
    if len(text) <= limit:
        return text
    return f'{text[:limit]}... ({len(text):,} characters)'


class CommandError(StructuredError, ValueError):
    """A light command or reset request that cannot be applied; the state is unchanged.

    Adapters key their throttled warnings on ``field`` and report ``str(error)``, so neither
    depends on the wording. The message quotes at most ``ECHO_CHARS`` of the value's repr.

    Args:
        field: the command field, e.g. ``action``, ``continuous[1]``, ``x``, ``challenge``.
        value: the value it had.
        allowed: what is allowed, e.g. ``an int in [0, 4] (left, right, ...)``.
    """

    def __init__(self, field: str, value: Any, allowed: str) -> None:
        super().__init__(f'{field} = {echo(value)} is not allowed; expected {allowed}.')
        self.field = field
        self.value = value
        self.allowed = allowed
