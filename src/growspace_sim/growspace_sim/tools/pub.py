"""One-shot publisher on rclpy: ``ros2 topic pub --once`` where ros2cli is not installed.

Example (the same YAML value as the ``ros2`` command line)::

    python -m growspace_sim.tools.pub light/command growspace_msgs/msg/LightCommand \\
        "{mode: 0, x: 0.3, width: 0.1}"

Waits (up to ``--wait`` seconds, 10 by default) until it is matched with every reader of the
topic that the ROS graph shows, and with the nodes named by ``--node``; publishes once with the
node's command QoS (reliable); then waits until every reader acknowledged the message, so that
none is lost on exit; and says which nodes got it. Waiting for the first reader only lost
messages: with ``growspace-record subscribe`` beside sim_node, the recorder often matched first
and sim_node missed the command. The graph cannot show a reader whose process has not been
discovered yet, and a running participant may be found only at its next announcement (Fast DDS
announces every 3 s; measured here: the second of two readers matched up to 3.1 s after the
first). So without ``--node`` it also waits until the readers have stayed the same for
``--settle`` seconds (``SETTLE_S``); with ``--node`` it publishes as soon as the named nodes
and every reader the graph shows are matched.
The value is checked against the type before anything starts: a misspelt field, or a value of
the wrong kind or out of its field's range (``step_id: -1``, ``x: abc``), is one line naming
the field, the value and what is allowed (exit 2).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
import os
import sys
import time

import yaml

from growspace_sim.ros import types
from growspace_sim.ros.interface import COMMAND_QOS
from growspace_sim.ros.names import DEFAULT_NAMESPACE


SETTLE_S = 3.5  # Fast DDS's participant announcement period (3 s), and a margin [s]
UNKNOWN_NODE = '_NODE_NAME_UNKNOWN_'  # the graph's node name of an endpoint it cannot place yet
POLL_S = 0.02  # how often the graph and the matches are looked at while waiting [s]


def is_node(wanted: str, node: str) -> bool:
    """Whether ``node`` (fully qualified) is the node named ``wanted``: fully qualified
    (``/chamber1/growspace_sim``) or by its name alone (``growspace_sim``, in any namespace)."""
    return node == wanted if wanted.startswith('/') else node.rsplit('/', 1)[1] == wanted


def graph_readers(transport, topic: str) -> tuple[list[str], list[str]]:
    """The subscriptions to ``topic`` that the ROS graph shows now, by node.

    Args:
        transport: an ``RclpyTransport`` with a publisher of ``topic``.
        topic: the topic, as given to the publisher.

    Returns:
        The fully qualified node names of the subscriptions our publisher can deliver to, and
        ``'node (reason)'`` for those it cannot (their QoS is incompatible, e.g. a
        transient-local reader of a volatile writer); each sorted, a node once per
        subscription. Both empty until the graph shows our own publisher.
    """
    from rclpy.qos import qos_check_compatible, QoSCompatibility

    # Compared as the graph reports both ends: the graph spells an unset deadline or
    # liveliness lease as "infinite", which rcl's check takes as set against the "default"
    # of the profile we created the publisher with.
    node, where = transport.node, transport.resolve(topic)
    ours = next((info.qos_profile for info in node.get_publishers_info_by_topic(where)
                 if (info.node_name, info.node_namespace) == (node.get_name(),
                                                              node.get_namespace())), None)
    if ours is None:
        return [], []
    compatible, incompatible = [], []
    for info in node.get_subscriptions_info_by_topic(where):
        name = f'{info.node_namespace.rstrip("/")}/{info.node_name}'
        verdict, reason = qos_check_compatible(ours, info.qos_profile)
        if verdict == QoSCompatibility.ERROR:
            incompatible.append(f'{name} ({reason.strip()})')
        else:
            compatible.append(name)
    return sorted(compatible), sorted(incompatible)


def wait_for_readers(transport, topic: str, nodes: Sequence[str], wait_s: float,
                     settle_s: float) -> tuple[list[str], list[str], list[str]]:
    """Spin until ``topic``'s publisher is matched with every reader the graph shows (at least
    one) and with each of ``nodes``, and the readers have stayed the same for ``settle_s``; or
    until ``wait_s`` passed.

    Returns:
        The readers (node names, one per subscription), the incompatible readers
        (``'node (reason)'``) and the names in ``nodes`` that are not among the readers.
    """
    deadline = time.monotonic() + wait_s
    seen, since = None, time.monotonic()
    while True:
        readers, incompatible = graph_readers(transport, topic)
        missing = [n for n in nodes if not any(is_node(n, r) for r in readers)]
        state = (readers, transport.matched_count(topic))
        # A reader's node name comes in a message of its own, after its endpoint.
        named = not any(UNKNOWN_NODE in reader for reader in readers)
        ready = bool(readers) and named and state[1] >= len(readers) and not missing
        now = time.monotonic()
        if state != seen:
            seen, since = state, now
        if (ready and now - since >= settle_s) or now >= deadline:
            return readers, incompatible, missing
        transport.spin_once(POLL_S)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m growspace_sim.tools.pub',
                                     description=__doc__.split('\n', 1)[0])
    parser.add_argument('topic', help=f'topic name, relative to {DEFAULT_NAMESPACE} (e.g. '
                        f'light/command) or absolute (e.g. /chamber1/reset)')
    parser.add_argument('type', help='message type, e.g. growspace_msgs/msg/LightCommand')
    parser.add_argument('values', nargs='?', default='{}', help='YAML mapping of field values')
    parser.add_argument('--wait', type=float, default=10.0,
                        help='seconds to wait for the readers, and again for their '
                             'acknowledgements')
    parser.add_argument('--node', action='append', default=[], metavar='NAME',
                        help='also wait until this node reads the topic: its name (growspace_sim '
                             "is sim_node's) or fully qualified (/chamber1/growspace_sim); "
                             'repeatable')
    parser.add_argument('--settle', type=float, metavar='SECONDS',
                        help='publish once the readers stayed the same this long (default: '
                             f'{SETTLE_S} without --node, 0 with it)')
    args = parser.parse_args(argv)
    for name in ('wait', 'settle'):
        value = getattr(args, name)
        if value is not None and not value >= 0:
            parser.error(f'--{name} must be >= 0 seconds, got {value}')
    if args.settle is None:
        args.settle = 0.0 if args.node else SETTLE_S
    try:
        values = yaml.safe_load(args.values) or {}
        if not isinstance(values, dict):
            raise ValueError(f'values must be a YAML mapping, got {args.values!r}')
        msg = types.from_plain(args.type, values)
    except (ValueError, TypeError, KeyError, yaml.YAMLError) as e:
        print(f'pub: {e.args[0] if isinstance(e, KeyError) else e}', file=sys.stderr)
        return 2
    from growspace_sim.node.presence import where_chambers_are
    from growspace_sim.node.rclpy_transport import RclpyTransport

    transport = RclpyTransport(f'growspace_pub_{os.getpid()}', DEFAULT_NAMESPACE)
    try:
        publish = transport.publisher(args.type, args.topic, COMMAND_QOS)
        topic = transport.resolve(args.topic)
        readers, incompatible, missing = wait_for_readers(transport, args.topic, args.node,
                                                          args.wait, args.settle)
        for reader in incompatible:
            print(f'pub: {reader} reads {topic} with a QoS that cannot match ours; it will not '
                  f'get this message', file=sys.stderr)
        if missing:
            print(f'pub: node {", ".join(missing)} does not read {topic} after {args.wait:g} s '
                  f'(its readers: {", ".join(readers) or "none"}); nothing published',
                  file=sys.stderr)
            return 1
        if not readers:
            print(f'pub: no subscriber on {topic} after {args.wait:g} s; publishing anyway; '
                  f'{where_chambers_are(transport)}', file=sys.stderr)
        matched = transport.matched_count(args.topic)
        if matched < len(readers):
            print(f'pub: matched only {matched} of the {len(readers)} readers of {topic} after '
                  f'{args.wait} s; publishing to those', file=sys.stderr)
        publish(msg)
        acknowledged = transport.flush(args.wait)
    finally:
        transport.close()
    to = f'to {matched} reader{"s" * (matched != 1)}' + (f' ({", ".join(readers)})'
                                                           if readers else '')
    if not acknowledged:
        print(f'pub: published on {topic} {to}, but not every reader acknowledged it within '
              f'{args.wait} s: it may be lost', file=sys.stderr)
        return 1
    print(f'published on {topic} {to}, acknowledged by every reader: {types.to_plain(msg)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
