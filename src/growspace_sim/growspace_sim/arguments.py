"""Argument checks shared by every console script: bad input ends before any work starts.

argparse calls an argument's ``type=`` on its value while it parses the command line, before
``main`` does anything; an ``argparse.ArgumentTypeError`` from it becomes
``prog: error: argument --episodes: -5 is not allowed; expected an integer >= 1``. ``Parser``
makes that (and every other argparse error) one line with exit status 2: plain argparse
prints its usage block first, which buries the sentence that says what is wrong.

    parser = Parser(prog='growspace-bench')
    parser.add_argument('--episodes', type=integer(1), default=200)
    parser.add_argument('--csv', type=new_file)
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
import math
import os
from pathlib import Path
from typing import Any, NoReturn, TypeVar

T = TypeVar('T')

ROS_DOMAIN_ID_MAX = 232  # the highest domain id DDS can map to UDP ports (ROS 2 docs, "Domain ID")


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line on stderr, exit status 2.

    Its subcommand parsers (``add_subparsers``) are ``Parser`` too.
    """

    def error(self, message: str) -> NoReturn:
        """Print ``prog: error: message`` on one line and exit with status 2."""
        self.exit(2, f'{self.prog}: error: {" ".join(message.split())} '
                     f'(see {self.prog} --help)\n')


def _range_text(kind: str, low: float | None, high: float | None, low_open: bool) -> str:
    if low is not None and high is not None:
        return f'{kind} in {"(" if low_open else "["}{low:g}, {high:g}]'
    if low is not None:
        return f'{kind} {">" if low_open else ">="} {low:g}'
    if high is not None:
        return f'{kind} <= {high:g}'
    return kind


def integer(low: int | None = None, high: int | None = None) -> Callable[[str], int]:
    """A ``type=`` for an integer in ``[low, high]`` (either bound may be left out)."""
    allowed = _range_text('an integer', low, high, False)

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not allowed; expected {allowed}') \
                from None
        if (low is not None and value < low) or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f'{value} is not allowed; expected {allowed}')
        return value
    parse.__name__ = allowed  # what argparse would name in its own messages
    return parse


def number(low: float | None = None, high: float | None = None, *,
           low_open: bool = False) -> Callable[[str], float]:
    """A ``type=`` for a finite number in ``[low, high]``; ``low_open`` excludes ``low``."""
    allowed = _range_text('a number', low, high, low_open)

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not allowed; expected {allowed}') \
                from None
        too_low = low is not None and (value <= low if low_open else value < low)
        if not math.isfinite(value) or too_low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f'{text} is not allowed; expected {allowed}')
        return value
    parse.__name__ = allowed
    return parse


SEED = integer(0)  # numpy's and Gymnasium's seeds are non-negative
DOMAIN_ID = integer(0, ROS_DOMAIN_ID_MAX)


def existing_file(text: str) -> str:
    """A ``type=`` for a file to read: it must exist and be a file."""
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f'{text!r}: the file does not exist')
    if not path.is_file():
        raise argparse.ArgumentTypeError(f'{text!r} is not a file')
    return text


def recording(text: str) -> str:
    """A ``type=`` for a recording to read: an MCAP file, or a split recording's folder."""
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f'{text!r}: no such file or folder')
    if not (path.is_file() or path.is_dir()):
        raise argparse.ArgumentTypeError(f'{text!r} is neither a file nor a folder')
    return text


def new_file(text: str) -> str:
    """A ``type=`` for a file to write: the folder it goes in must exist and be writable.

    Whether the file itself may be replaced is the command's own rule (``--overwrite``).
    """
    if not text:
        raise argparse.ArgumentTypeError("'' is not allowed; expected a file name")
    path = Path(text)
    folder = path.parent
    if path.is_dir():
        raise argparse.ArgumentTypeError(f'{text!r} is a folder; expected a file name')
    if not folder.is_dir():
        raise argparse.ArgumentTypeError(f'{text!r}: the folder {str(folder)!r} does not exist')
    if not os.access(folder, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f'{text!r}: the folder {str(folder)!r} is not writable')
    return text


def folder(text: str) -> str:
    """A ``type=`` for a folder to write into (created with its parents when missing): it must
    not be a file, and the nearest folder that exists must be writable."""
    if not text:
        raise argparse.ArgumentTypeError("'' is not allowed; expected a folder")
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f'{text!r} is a file; expected a folder')
    existing = next((p for p in (path, *path.absolute().parents) if p.exists()), None)
    if existing is not None and not existing.is_dir():
        raise argparse.ArgumentTypeError(f'{text!r}: {str(existing)!r} is a file, not a folder')
    if existing is not None and not os.access(existing, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f'{text!r}: the folder {str(existing)!r} is not '
                                         f'writable')
    return text


def comma_separated(item: Callable[[str], T], *, empty: bool = False) -> Callable[[str], list[T]]:
    """A ``type=`` for ``a,b,c``: each item through ``item`` (a ``type=``, or a function that
    raises ``ValueError`` with a sentence); ``empty`` allows no item at all (``''``)."""
    def parse(text: str) -> list[T]:
        parts = [part.strip() for part in text.split(',')] if text.strip() else []
        if not parts and not empty:
            raise argparse.ArgumentTypeError("'' is not allowed; expected one or more, "
                                             'comma-separated')
        values = []
        for part in parts:
            try:
                values.append(item(part))
            except (argparse.ArgumentTypeError, ValueError) as e:
                raise argparse.ArgumentTypeError(str(e)) from None
        return values
    parse.__name__ = 'comma-separated list'
    return parse


def checked(check: Callable[[str], Any]) -> Callable[[str], str]:
    """A ``type=`` that keeps the text when ``check(text)`` raises no ``ValueError`` (whose
    sentence becomes the error), e.g. ``checked(tasks.get)`` for a challenge name."""
    def parse(text: str) -> str:
        try:
            check(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
        return text
    parse.__name__ = getattr(check, '__name__', 'value')
    return parse


def namespace(text: str) -> str:
    """A ``type=`` for a ROS namespace (``/lab/chamber1``; relative ones are taken from ``/``),
    checked as rcl checks it; the text is kept as given."""
    from growspace_sim.ros.names import normalize_namespace

    try:
        normalize_namespace(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(f'{text!r} is not allowed: {e}') from None
    return text


def json_object(text: str) -> dict[str, Any]:
    """A ``type=`` for a JSON object (``'{"light_density": 400}'``)."""
    import json

    try:
        value = json.loads(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(f'{text!r} is not JSON ({e})') from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f'{text!r} is not allowed; expected a JSON object '
                                         "('{\"name\": value, ...}')")
    return value
