"""Joining a Ray cluster: this machine's token checked first, and a refusal said in one line.

With ``RAY_AUTH_MODE=token`` and no token, Ray 2.60's ``ray.init`` raises its
``AuthenticationError`` (a traceback); with a wrong token it retries for about 20 s, printing a
warning a second, before it gives up. ``token_source`` finds the token where Ray documents it
looks (https://docs.ray.io/en/latest/ray-core/internals/token-authentication.html, "Token
Sources and Precedence"), so that a missing one is said before anything connects;
``join`` connects with one attempt and keeps Ray's retry warnings off the terminal, so that a
refused token is one line at once.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
import contextlib
import os
from pathlib import Path
import sys
import tempfile
from typing import Any

AUTH_MODE_VAR = 'RAY_AUTH_MODE'
TOKEN_VAR = 'RAY_AUTH_TOKEN'
TOKEN_PATH_VAR = 'RAY_AUTH_TOKEN_PATH'
# How many times Ray tries the cluster's GCS before it gives up (about 1 s apart); Ray's default
# is 20. The address already answered (trials._check_answers), so a failed try is a refusal,
# not a server still starting: one is enough.
CONNECT_TRIES_VAR = 'RAY_gcs_server_port_wait_time_s'
CONNECT_TRIES = '1'
COPY_TOKEN = "copy the head's ~/.ray/auth_token to this machine's ~/.ray/auth_token"


def token_source() -> str | None:
    """Where Ray will read this machine's token, in Ray's order; None if nowhere.

    ``RAY_AUTH_TOKEN`` if set and not empty; else the file ``RAY_AUTH_TOKEN_PATH`` names (Ray
    reads no other then); else ``~/.ray/auth_token``.

    Raises:
        ConnectionError: ``RAY_AUTH_TOKEN_PATH`` names a file that cannot be read or is empty
            (Ray aborts on that rather than looking elsewhere).
    """
    if os.environ.get(TOKEN_VAR):
        return TOKEN_VAR
    named = os.environ.get(TOKEN_PATH_VAR)
    path = Path(named) if named else Path.home() / '.ray' / 'auth_token'
    try:
        held = bool(path.read_text().strip())
    except OSError as error:
        if named:
            raise ConnectionError(f'{TOKEN_PATH_VAR}={named}: {error.strerror or error}; Ray '
                                  'reads the token from that file only') from None
        return None
    if not held and named:
        raise ConnectionError(f'{TOKEN_PATH_VAR}={named} is empty; Ray reads the token from '
                              'that file only')
    return str(path) if held else None


def check_token(address: str) -> None:
    """Fail before connecting where Ray would refuse at once: token mode and no token.

    Raises:
        ConnectionError: one line naming what is missing and how to provide it.
    """
    if os.environ.get(AUTH_MODE_VAR, '').lower() != 'token':
        return
    if token_source() is None:
        raise ConnectionError(
            f'{AUTH_MODE_VAR}=token but this machine has no Ray token for the cluster at '
            f'{address}: {COPY_TOKEN} (or set {TOKEN_PATH_VAR} or {TOKEN_VAR})')


def join(address: str, init: Callable[[], Any]) -> Any:
    """Call ``init`` (``ray.init`` of the cluster at ``address``) with one connection attempt,
    Ray's output held back: shown if it joins, dropped (but for the reason) if it does not.

    Raises:
        ConnectionError: one line: the cluster refused this machine's token, or wants one, or
            Ray's own reason.
    """
    from ray.exceptions import AuthenticationError  # noqa: PLC0415

    tries = {} if CONNECT_TRIES_VAR in os.environ else {CONNECT_TRIES_VAR: CONNECT_TRIES}
    with _held_stderr() as held, environ(tries):
        try:
            return init()
        except (AuthenticationError, ConnectionError, RuntimeError) as error:
            held.drop()
            raise ConnectionError(_refusal(address, error)) from None


def _refusal(address: str, error: BaseException) -> str:
    """One line for a failed join, from Ray's exception chain (which holds tracebacks' text)."""
    text = ''
    while error is not None:
        text += f'\n{type(error).__name__}: {error}'
        error = error.__cause__ or error.__context__
    if 'InvalidAuthToken' in text or 'Unauthenticated' in text or \
            'AuthenticationError' in text:
        if os.environ.get(AUTH_MODE_VAR, '').lower() != 'token':
            return (f'the Ray cluster at {address} wants a token: set {AUTH_MODE_VAR}=token'
                    f'{"" if token_source() else f" and {COPY_TOKEN}"}')
        return (f"the Ray cluster at {address} refused this machine's token (from "
                f'{token_source()}): {COPY_TOKEN}')
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    return f'could not join the Ray cluster at {address} ({lines[-1] if lines else "no reason"})'


class _Held:
    """What was written to file descriptor 2 inside ``_held_stderr``."""

    def __init__(self) -> None:
        self.dropped = False

    def drop(self) -> None:
        self.dropped = True


@contextlib.contextmanager
def _held_stderr() -> Iterator[_Held]:
    """Send file descriptor 2 (Python's and Ray's C++ logging alike) to a temporary file, and
    write it out at the end unless ``drop()`` was called."""
    held = _Held()
    sys.stderr.flush()
    with tempfile.TemporaryFile() as sink:
        saved = os.dup(2)
        os.dup2(sink.fileno(), 2)
        try:
            yield held
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            if not held.dropped:
                sink.seek(0)
                os.write(2, sink.read())


@contextlib.contextmanager
def environ(values: Mapping[str, str]) -> Iterator[None]:
    """Set environment variables for the block (and the processes started inside it)."""
    saved = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
