"""``sim_node`` entry point: the chamber node on rclpy when it imports, else on Cyclone DDS.

GROWSPACE_TRANSPORT=dds|rclpy forces one. Exit codes: 0 after SIGINT/SIGTERM (the recording is
finished first), 2 for an invalid parameter or argument (one line naming it, its value and
what is allowed on stderr).

SIGINT and SIGTERM only set a flag that the DDS spin loop checks every ``SPIN_S``; unlike
``recording.stop_on_signals`` (which raises wherever the main thread is) this never cuts a
lockstep step between its state change and its StepResult, or a DDS write. Either way the node
is closed in ``finally``, which finishes the recording. rclpy mode gets the same from rclpy's own
handler (ExternalShutdownException).
"""

from __future__ import annotations

import importlib.util
import logging
import os
import signal
import sys
import threading
from typing import Any, Sequence

from growspace_sim.node import params
from growspace_sim.node.chamber_node import ChamberNode, Recorder
from growspace_sim.node.params import ParamError

TRANSPORT_ENV = 'GROWSPACE_TRANSPORT'
EXIT_BAD_PARAM = 2
SPIN_S = 0.1  # how late a signal can be noticed in DDS mode [s]

log = logging.getLogger('growspace_sim.sim_node')


def make_recorder(path: str) -> Recorder | None:
    """The MCAP recorder of ``record_path``, or None when it is empty.

    Raises:
        ParamError: the recorder is unavailable or the file cannot be created.
    """
    if not path:
        return None
    try:
        from growspace_sim.recording import McapRecorder, RecordingError
    except ImportError as e:
        raise ParamError(f'record_path = {path!r} needs growspace_sim.recording: {e}') from None
    try:
        return McapRecorder(path)
    except RecordingError as e:  # exists already (never overwritten), no directory, no space
        raise ParamError(f'record_path = {path!r} cannot be written: {e}') from None


def choose_transport() -> str:
    """'rclpy' or 'dds': the environment variable, else rclpy when importable.

    Raises:
        ParamError: the environment variable has another value.
    """
    choice = os.environ.get(TRANSPORT_ENV, '').strip().lower()
    if choice not in ('', 'dds', 'rclpy'):
        raise ParamError(f'{TRANSPORT_ENV} = {choice!r} is not allowed; expected dds or rclpy.')
    if choice:
        return choice
    return 'rclpy' if importlib.util.find_spec('rclpy') is not None else 'dds'


def run_dds(argv: Sequence[str]) -> int:
    """Run the node on Cyclone DDS until SIGINT or SIGTERM."""
    from growspace_sim.node.transport import DdsTransport

    try:
        ros_args = params.parse_ros_args(argv)
        cfg, node_params = params.build(ros_args.params)
        transport = DdsTransport(ros_args.node_name, ros_args.namespace)
    except ValueError as e:  # ParamError, bad ROS_DOMAIN_ID, bad node name or namespace
        print(f'sim_node: invalid parameter: {e}', file=sys.stderr)
        return EXIT_BAD_PARAM
    try:
        recorder = make_recorder(node_params.record_path)
    except ParamError as e:
        transport.close()
        print(f'sim_node: invalid parameter: {e}', file=sys.stderr)
        return EXIT_BAD_PARAM
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    node = None
    try:
        node = ChamberNode(transport, cfg, node_params, recorder)
        log.info('sim_node on Cyclone DDS: %s, %s mode, seed %s%s', transport.resolve('~'),
                 node_params.mode, node.seed,
                 f', recording to {node_params.record_path}' if recorder else '')
        while not stop.is_set():
            transport.spin_once(SPIN_S)
    finally:
        if node is not None:
            node.close()
        elif recorder is not None:
            recorder.close()
        transport.flush(0.5)
        transport.close()
    log.info('sim_node stopped')
    return 0


def run_rclpy(argv: Sequence[str]) -> int:
    """Run the node on rclpy (the Jazzy talker.py shutdown pattern)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    from growspace_sim.node.rclpy_transport import RclpyTransport

    rclpy.init(args=[sys.argv[0], *argv])
    transport: Any = None
    node: ChamberNode | None = None
    code = 0
    try:
        transport = RclpyTransport(params.DEFAULT_NODE_NAME)
        try:
            cfg, node_params = params.build(transport.declare_parameters())
            recorder = make_recorder(node_params.record_path)
        except ValueError as e:
            print(f'sim_node: invalid parameter: {e}', file=sys.stderr)
            return EXIT_BAD_PARAM
        node = ChamberNode(transport, cfg, node_params, recorder)
        transport.on_parameter_change(node.propose)
        rclpy.spin(transport.node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.close()
        if transport is not None:
            transport.close()
        rclpy.try_shutdown()
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``sim_node``."""
    logging.basicConfig(level=logging.INFO, format='[%(levelname)s] [%(name)s]: %(message)s')
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        kind = choose_transport()
    except ParamError as e:
        print(f'sim_node: {e}', file=sys.stderr)
        return EXIT_BAD_PARAM
    return run_rclpy(argv) if kind == 'rclpy' else run_dds(argv)


if __name__ == '__main__':
    sys.exit(main())
