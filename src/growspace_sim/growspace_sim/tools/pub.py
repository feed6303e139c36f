"""One-shot publisher on rclpy: ``ros2 topic pub --once`` where ros2cli is not installed.

Example (the same YAML value as the ``ros2`` command line)::

    python -m growspace_sim.tools.pub light/command growspace_msgs/msg/LightCommand \\
        "{mode: 0, x: 0.3, width: 0.1}"

Waits until a subscriber matched (up to ``--wait`` seconds), publishes once with the node's
command QoS (reliable), and waits for the acknowledgement, so the message is not lost on exit.
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


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m growspace_sim.tools.pub',
                                     description=__doc__.split('\n', 1)[0])
    parser.add_argument('topic', help=f'topic name, relative to {DEFAULT_NAMESPACE} (e.g. '
                        f'light/command) or absolute (e.g. /chamber1/reset)')
    parser.add_argument('type', help='message type, e.g. growspace_msgs/msg/LightCommand')
    parser.add_argument('values', nargs='?', default='{}', help='YAML mapping of field values')
    parser.add_argument('--wait', type=float, default=5.0, help='seconds to wait for a reader')
    args = parser.parse_args(argv)
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
        deadline = time.monotonic() + args.wait
        while not transport.matched(args.topic) and time.monotonic() < deadline:
            transport.spin_once(0.02)
        if not transport.matched(args.topic):
            print(f'pub: no subscriber on {topic} after {args.wait} s; publishing anyway; '
                  f'{where_chambers_are(transport)}', file=sys.stderr)
        publish(msg)
        transport.flush(args.wait)
    finally:
        transport.close()
    print(f'published on {topic}: {types.to_plain(msg)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
