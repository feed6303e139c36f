"""ROS 2 name rules as rcl applies them, for what runs without rclpy (the in-process node).

`resolve_topic('plant/state', 'sim', '/chamber1')` gives `/chamber1/plant/state` and `~/debug`
gives `/chamber1/sim/debug`, as ``rclpy.expand_topic_name`` does. On ROS,
rcl itself resolves names and applies remappings.
"""

from __future__ import annotations

import re

MAX_NODE_NAME_LENGTH = 255  # RMW_NODE_NAME_MAX_NAME_LENGTH
# The chamber's namespace unless ``-r __ns:=`` (or a program's option) says otherwise: every
# program we ship (sim_node, gantry_node, camera_node, view_node, teleop, growspace-record,
# tools.pub) and the launch file meet there, so following the README they find each other.
DEFAULT_NAMESPACE = '/growspace'

_TOKEN = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')
_SUBSTITUTION = re.compile(r'\{([^{}]*)\}')


class InvalidNameError(ValueError):
    """Raised for a node name, namespace or topic name that rcl would reject."""


def _check_tokens(name: str, what: str) -> None:
    # name is absolute here: every token between slashes must be a valid identifier.
    if name == '/':
        return
    if name.endswith('/'):
        raise InvalidNameError(f'{what} {name!r} must not end with "/"')
    for token in name[1:].split('/'):
        if not token:
            raise InvalidNameError(f'{what} {name!r} must not contain "//"')
        if not _TOKEN.fullmatch(token):
            bad = next((c for c in token if not (c.isascii() and (c.isalnum() or c == '_'))),
                       None)
            reason = f'contains {bad!r}' if bad else 'starts with a digit'
            raise InvalidNameError(
                f'{what} {name!r}: token {token!r} {reason}; tokens are [A-Za-z_][A-Za-z0-9_]*')


def validate_node_name(name: str) -> None:
    """Check a node name (no slashes, not starting with a digit).

    Args:
        name: The node name, e.g. `growspace_sim`.

    Raises:
        InvalidNameError: The name is invalid; the message says why.
    """
    if not name:
        raise InvalidNameError('Node name must not be empty')
    if len(name) > MAX_NODE_NAME_LENGTH:
        raise InvalidNameError(f'Node name is {len(name)} characters, at most '
                               f'{MAX_NODE_NAME_LENGTH} are allowed')
    if not _TOKEN.fullmatch(name):
        raise InvalidNameError(f'Node name {name!r} must match [A-Za-z_][A-Za-z0-9_]*')


def normalize_namespace(namespace: str) -> str:
    """Make a namespace absolute (as rcl does for `ns` without a leading slash) and check it.

    Args:
        namespace: e.g. `''`, `'/'`, `'chamber1'`, `'/lab/chamber1'`.

    Returns:
        The absolute namespace, `/` for the empty one.

    Raises:
        InvalidNameError: The namespace is invalid.
    """
    if not namespace:
        return '/'
    if not namespace.startswith('/'):
        namespace = '/' + namespace
    _check_tokens(namespace, 'Namespace')
    return namespace


def resolve_topic(name: str, node_name: str, namespace: str = '/') -> str:
    """Expand a topic name into its fully qualified form, following rcl_expand_topic_name.

    Relative names go into the namespace, `~` is the node's private namespace, and the
    substitutions `{node}` and `{ns}`/`{namespace}` are replaced.

    Args:
        name: Topic name as given by the user, e.g. `plant/state`, `/clock`, `~/debug`.
        node_name: Name of the node owning the topic.
        namespace: The node's namespace.

    Returns:
        The fully qualified name, e.g. `/chamber1/plant/state`.

    Raises:
        InvalidNameError: The name, node name or namespace is invalid.
    """
    validate_node_name(node_name)
    namespace = normalize_namespace(namespace)
    if not name:
        raise InvalidNameError('Topic name must not be empty')
    if '~' in name and not (name == '~' or (name.startswith('~/') and '~' not in name[1:])):
        raise InvalidNameError(f'Topic name {name!r}: "~" is only allowed as "~" or a "~/" prefix')

    substitutions = {'node': node_name, 'ns': namespace, 'namespace': namespace}

    def substitute(match: re.Match) -> str:
        key = match.group(1)
        if key not in substitutions:
            raise InvalidNameError(f'Topic name {name!r}: unknown substitution {{{key}}}')
        return substitutions[key]

    expanded = _SUBSTITUTION.sub(substitute, name)
    if '{' in expanded or '}' in expanded:
        raise InvalidNameError(f'Topic name {name!r} has unbalanced braces')
    private = namespace.rstrip('/') + '/' + node_name
    if expanded.startswith('~'):
        expanded = private + expanded[1:]
    elif not expanded.startswith('/'):
        expanded = namespace.rstrip('/') + '/' + expanded
    if expanded.startswith('//'):
        expanded = expanded[1:]  # '{ns}/x' in the root namespace
    _check_tokens(expanded, 'Topic name')
    return expanded
