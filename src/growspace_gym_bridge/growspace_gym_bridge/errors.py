"""What the bridge raises: each error names the topic, the ids and the timeout involved.

Every one survives ``pickle`` with its text and fields (``StructuredError``), so a vector env's
worker hands its parent the very error it saw.
"""

from __future__ import annotations

from collections.abc import Sequence

from growspace_sim.core.errors import StructuredError


class BridgeError(StructuredError):
    """Base class of the errors of the Gymnasium bridge."""


class BridgeTimeout(BridgeError, TimeoutError):
    """No (complete) reply arrived in time.

    Args:
        topic: fully qualified topic that did not deliver.
        timeout_s: how long the bridge waited [s].
        step_id: lockstep step id waited for (0 for a reset).
        reset_id: id of the reset of the episode.
        detail: what was expected, in words.
    """

    def __init__(self, topic: str, timeout_s: float, step_id: int = 0, reset_id: int = 0,
                 detail: str = 'no reply') -> None:
        self.topic = topic
        self.timeout_s = timeout_s
        self.step_id = step_id
        self.reset_id = reset_id
        super().__init__(f'{topic}: {detail} for step_id {step_id} (reset_id {reset_id}) '
                         f'within the timeout of {timeout_s:g} s')


class NodeDied(BridgeError, RuntimeError):
    """The sim node is gone while the bridge waited for it.

    Args:
        namespace: the chamber's namespace.
        returncode: the node's exit status (negative: killed by that signal), None if unknown
            (a node the bridge attached to but did not start).
        stderr_tail: the last lines the node wrote to stderr.
        waiting_for: what the bridge was waiting for (topic, ids).
    """

    def __init__(self, namespace: str, returncode: int | None, stderr_tail: Sequence[str] = (),
                 waiting_for: str = '') -> None:
        self.namespace = namespace
        self.returncode = returncode
        self.stderr_tail = list(stderr_tail)
        status = 'is gone' if returncode is None else f'exited with code {returncode}'
        text = f'sim node {namespace} {status}'
        if waiting_for:
            text += f' while the bridge waited for {waiting_for}'
        if self.stderr_tail:
            text += '; last stderr lines:\n  ' + '\n  '.join(self.stderr_tail)
        super().__init__(text)


class CommandRejected(BridgeError, ValueError):
    """The node answered a command or reset with an error (the state is unchanged)."""
