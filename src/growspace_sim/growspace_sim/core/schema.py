"""Declared settings: each field of a settings dataclass is declared once, with ``param``.

A declaration holds what a user must know of a setting (its meaning, unit, allowed values and
when a change takes effect) beside its default, so one source gives the validation
(``check``), the ROS parameter descriptors and params file (``node.params``) and the tables in
the README (``markdown_table``)::

    @dataclass(frozen=True)
    class LampSettings:
        power: float = param(1.0, 'lamp power while lit', unit='fraction of full power',
                             bounds=Bounds(0.0, 1.0))

        def __post_init__(self) -> None:
            check(self)

Plain dataclass field metadata, no library: the core stays importable with numpy alone, and a
validation library (pydantic) would cost ~180 ms of start-up in every process for what fits here
(its errors would also not name the field, the value and the range in our one-line form).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
import dataclasses
from dataclasses import dataclass
import math
import re
from typing import Any

from growspace_sim.core.errors import echo

# When a new value takes effect in a running node.
AT_RESET = 'at the next reset'
AT_ONCE = 'at once'
AT_ONCE_REALTIME = 'at once, in realtime mode (read-only in lockstep)'
AT_START = 'at start-up (read-only)'
_KIND_NAMES = {bool: 'a bool (true or false)', int: 'an integer', float: 'a number',
               str: 'a string', tuple: 'a list of integers'}


@dataclass(frozen=True)
class Bounds:
    """The values a number field allows; also its ROS parameter's range.

    Attributes:
        low: Smallest value (excluded if ``low_open``).
        high: Largest value (included; ``math.inf`` for no limit).
        integer: Only ints are allowed (else any finite number).
        low_open: ``low`` itself is not allowed (e.g. a fraction that must be positive).
        sentinel: One more allowed value outside ``[low, high]`` with a meaning of its own.
    """

    low: float
    high: float = math.inf
    integer: bool = False
    low_open: bool = False
    sentinel: int | None = None

    def __str__(self) -> str:
        if math.isinf(self.high):
            return f'{">" if self.low_open else ">="} {self.low}'
        return f'{"]" if self.low_open else "["}{self.low}, {self.high}]'

    def check(self, name: str, value: object) -> None:
        """Raise ``ValueError`` naming the field, the value and what is allowed."""
        kind = int if self.integer else (int, float)
        if isinstance(value, bool) or not isinstance(value, kind):
            raise ValueError(f'{name} must be {"an int" if self.integer else "a number"}, '
                             f'got {echo(value)}.')
        if self.sentinel is not None and value == self.sentinel:
            return
        if not math.isfinite(value) or value > self.high or value < self.low \
                or (self.low_open and value == self.low):
            also = '' if self.sentinel is None else f' or {self.sentinel}'
            where = f'in {self}' if math.isfinite(self.high) else str(self)
            raise ValueError(f'{name} must be {where}{also}, got {echo(value)}.')


@dataclass(frozen=True)
class Param:
    """What a user must know of one setting, besides its name and default.

    Attributes:
        doc: What it means, e.g. 'initial beam width'.
        unit: Its unit ('m', 's', 'Hz', 'fraction of the width', ...); '' for none.
        bounds: The range of a number (of each element of a list).
        choices: The allowed strings, or a function giving them (a registry that can grow).
        accept: Checks a value instead of ``choices`` (which then only document it): raises
            ``ValueError`` naming the value for one it refuses (a registry that loads on use).
        pattern: A regular expression a string must match in full, with ``pattern_doc``
            saying it in words.
        rule: What else is allowed, in words (rules that join fields, sentinels' meaning).
        when: When a change takes effect in a running node (``AT_RESET``, ``AT_ONCE``, ...).
    """

    doc: str
    unit: str = ''
    bounds: Bounds | None = None
    choices: tuple[str, ...] | Callable[[], tuple[str, ...]] = ()
    accept: Callable[[Any], object] | None = None
    pattern: str = ''
    pattern_doc: str = ''
    rule: str = ''
    when: str = AT_START

    @property
    def allowed(self) -> tuple[str, ...]:
        """The allowed strings (empty: any)."""
        return self.choices() if callable(self.choices) else self.choices

    @property
    def description(self) -> str:
        """Unit and meaning, e.g. 'm; width of the chamber'."""
        return f'{self.unit}; {self.doc}' if self.unit else self.doc

    @property
    def constraints(self) -> str:
        """What is allowed beyond the type and range, in words (ROS additional constraints)."""
        return '; '.join(filter(None, (
            f'one of {", ".join(self.allowed)}' if self.allowed else '',
            'greater than 0' if self.bounds is not None and self.bounds.low_open
            and self.bounds.low == 0 else '',
            self.pattern_doc, self.rule)))

    def allowed_text(self, default: Any) -> str:
        """Everything allowed, in words: range (and sentinel), choices, form and rules."""
        bounds = ''
        if self.bounds is not None:
            bounds = ('each in ' if isinstance(default, tuple) else '') + str(self.bounds)
            if self.bounds.sentinel is not None:
                bounds += f' or {self.bounds.sentinel}'
        return '; '.join(filter(None, (
            bounds, f'one of {", ".join(self.allowed)}' if self.allowed else '',
            self.pattern_doc, self.rule)))

    def check(self, name: str, value: Any) -> None:
        """Check a value of the field's own type against the declaration.

        Raises:
            ValueError: naming the field, the value and what is allowed.
        """
        if self.accept is not None:
            self.accept(value)
        elif self.allowed and value not in self.allowed:
            raise ValueError(f'{name} must be one of {self.allowed}, got {echo(value)}.')
        if self.pattern and (not isinstance(value, str)
                             or not re.fullmatch(self.pattern, value)):
            raise ValueError(f'{name} must be {self.pattern_doc}, got {echo(value)}.')
        if self.bounds is not None:
            if isinstance(value, tuple):
                for item in value:
                    try:
                        self.bounds.check(f'each of {name}', item)
                    except ValueError as e:
                        raise ValueError(f'{str(e)[:-1]} in {echo(value)}.') from None
            else:
                self.bounds.check(name, value)


def param(default: Any, doc: str, **declaration: Any) -> Any:
    """A dataclass field with its declaration (the keyword arguments of ``Param``)."""
    return dataclasses.field(default=default, metadata={'param': Param(doc, **declaration)})


def declared(cls: type) -> Iterator[tuple[dataclasses.Field, Param]]:
    """The declared fields of a settings dataclass, in field order."""
    for field in dataclasses.fields(cls):
        if 'param' in field.metadata:
            yield field, field.metadata['param']


def kind(default: Any) -> type:
    """The type a setting's values have: that of its default (bool before int)."""
    for t in (bool, int, float, str, tuple):
        if isinstance(default, t):
            return t
    raise TypeError(f'no settings type for {default!r}')


def check(obj: Any) -> None:
    """Validate every declared field of a settings object: type, then its declaration.

    Raises:
        ValueError: for the first field that is wrong, naming it, its value and what is allowed.
    """
    for field, declaration in declared(type(obj)):
        value = getattr(obj, field.name)
        expected = kind(field.default)
        ok = isinstance(value, expected) and not (expected is not bool and isinstance(value, bool))
        if expected is float:  # an int is a number too (a missing '.0' on the command line)
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if expected is tuple:
            ok = isinstance(value, tuple) and all(
                isinstance(v, int) and not isinstance(v, bool) for v in value)
        if not ok:
            raise ValueError(f'{field.name} must be {_KIND_NAMES[expected]}, got {echo(value)}.')
        declaration.check(field.name, value)


def coerce(default: Any, name: str, value: Any) -> Any:
    """A value from a params file or the command line, in the setting's own type.

    Integers are taken for numbers (ROS would refuse ``-p rate_hz:=20`` for a double) and lists
    for tuples; nothing else is converted.

    Raises:
        ValueError: naming the setting and the value, for a value of another type.
    """
    expected = kind(default)
    if expected is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if expected is tuple and isinstance(value, (list, tuple)) and all(
            isinstance(v, int) and not isinstance(v, bool) for v in value):
        return tuple(value)
    if isinstance(value, expected) and not (expected is int and isinstance(value, bool)):
        return value
    raise ValueError(f'{name} must be {_KIND_NAMES[expected]}, got {echo(value)}.')


def markdown_table(*classes: type) -> str:
    """A README table of the declared settings of some dataclasses, in field order."""
    lines = ['| parameter | default | unit | allowed | meaning | applies |',
             '|---|---|---|---|---|---|']
    for cls in classes:
        for field, p in declared(cls):
            allowed = p.allowed_text(field.default)
            default = list(field.default) if isinstance(field.default, tuple) else field.default
            default = '""' if default == '' else repr(default)
            lines.append(f'| `{field.name}` | `{default}` | {p.unit} | {allowed} | {p.doc} '
                         f'| {p.when} |')
    return '\n'.join(lines)
