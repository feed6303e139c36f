"""``sim_node`` entry point: the chamber node on rclpy (the Jazzy ``talker.py`` pattern).

Exit codes: 0 after SIGINT or SIGTERM, whenever it comes (the recording is finished first),
and for ``--help``; 2 for an invalid parameter (one line on stderr naming it, its value and what
is allowed), a ROS command line rcl cannot parse (a missing or broken params file, a bad ``-p``
or ``-r``) or an argument that is not a ROS one (``-p x:=1`` without ``--ros-args``, which rclpy
would leave to a program that ignores it). Every node runs in ``/growspace`` unless
``-r __ns:=`` says otherwise.
Unknown parameters (a typo in ``-p`` or a params file) are reported and ignored, as ROS does for
undeclared ones, but never silently.

Signals: ours only set a flag (so nothing raises KeyboardInterrupt), which ends the spin loop
between two callbacks, so a lockstep step is never cut between its state change and its
StepResult; a signal that comes before rclpy is up (imports, start-up) ends the node as soon as
it would start spinning. rclpy's own handlers are not installed: they would shut the context
down from their thread while a timer callback still publishes ("publisher's context is
invalid"). Closing then runs in order (the node's recording, the executor, the node, the
context) and is bounded: a second SIGINT or SIGTERM ends the process at once, and if closing
takes longer than ``CLOSE_TIMEOUT_S`` (a hang in native code, where no Python signal handler
runs), faulthandler writes every thread's stack to stderr and exits with status 1.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
import contextlib
import faulthandler
import logging
import os
import re
import signal
import sys
import threading
from typing import Any, Protocol

from growspace_sim.node import params
from growspace_sim.node.chamber_node import ChamberNode, Recorder
from growspace_sim.node.params import ParamError
from growspace_sim.ros.names import DEFAULT_NAMESPACE

EXIT_BAD_PARAM = 2
USAGE = """usage: {executable} [--ros-args [-p NAME:=VALUE] [--params-file FILE] [-r __ns:=/NS]]

Runs in the namespace {namespace} unless -r __ns:= says otherwise. Its parameters, their units,
ranges and when a change applies: the README, or `ros2 param describe` on the running node."""
CLOSE_TIMEOUT_S = 10.0  # closing longer than this is a hang: stacks to stderr, exit 1 [s]

log = logging.getLogger('growspace_sim.sim_node')


def make_recorder(path: str, max_bytes: int = 0, max_duration_s: float = 0.0,
                  append: bool = False) -> Recorder | None:
    """The MCAP recorder of ``record_path``, or None when it is empty.

    Args:
        path: ``record_path``: a file, or with a limit a split recording's directory.
        max_bytes: ``record_max_bytes`` (0 = no size limit).
        max_duration_s: ``record_max_duration_s`` (0 = no duration limit).
        append: Continue an existing split recording (a resumed run) with a new file.

    Raises:
        ParamError: the recorder is unavailable or the file cannot be created.
    """
    if not path:
        return None
    try:
        from growspace_sim.recording import McapRecorder, RecordingError, SplitRecorder
    except ImportError as e:
        raise ParamError(f'record_path = {path!r} needs growspace_sim.recording: {e}') from None
    try:
        if max_bytes or max_duration_s or append:
            return SplitRecorder(path, max_bytes=max_bytes, max_duration_s=max_duration_s,
                                 append=append)
        return McapRecorder(path)
    except RecordingError as e:  # exists already (never overwritten), no directory, no space
        raise ParamError(f'record_path = {path!r} cannot be written: {e}') from None


def load_resume_point(path: str) -> Any:
    """``resume_path``: the recording re-simulated to its last step (a damaged last file of a
    split recording is repaired first), or None when it is empty.

    Raises:
        ParamError: the recording cannot be read or does not re-simulate bit for bit.
    """
    if not path:
        return None
    from growspace_sim.recording import is_split_recording, RecordingError, repair
    from growspace_sim.replay import ReplayError, resume_point

    try:
        if is_split_recording(path):
            repair(path)
        return resume_point(path)
    except (ReplayError, RecordingError, OSError) as e:
        raise ParamError(f'resume_path = {path!r} cannot be resumed: {e}') from None


def installed_executable() -> str:
    """The colcon-installed ``sim_node``: what ``ros2 run growspace_sim sim_node`` starts."""
    from ament_index_python.packages import get_package_prefix

    return os.path.join(get_package_prefix('growspace_sim'), 'lib', 'growspace_sim', 'sim_node')


_ROS_RULES = {  # rcl's names of the rules a user writes, and what each must look like
    'remap rule': 'FROM:=TO of valid ROS names, e.g. -r __ns:=/lab/chamber1 (tokens of letters, '
                  'digits and _, one / between them)',
    'parameter override rule': 'NAME:=VALUE, e.g. -p seed:=3',
}


def ros_arguments_error(argv: Sequence[str]) -> str | None:
    """Why rcl cannot parse a ROS command line, in one line; None if it can.

    rcl parses it (params files included) exactly as ``rclpy.init`` would, but without a
    context, so nothing is started and rcl logs nothing.

    Args:
        argv: the whole command line, executable first.
    """
    from rclpy.logging import LoggingSeverity, set_logger_level
    from rclpy.utilities import remove_ros_args

    # rcl also logs a warning of its own for some errors (a namespace that is not fully
    # qualified), a second line that says less than the one we print.
    set_logger_level('rcl', LoggingSeverity.ERROR)
    try:
        remove_ros_args(list(argv))
    except RuntimeError as e:  # rclpy's RCLInvalidROSArgsError and UnknownROSArgsError
        text = re.sub(r', at \S+:\d+', '', str(e))  # rcl's source locations mean nothing here
        text = ' '.join(text.removeprefix('Failed to parse ROS arguments: ').split())
        for kind, allowed in _ROS_RULES.items():  # rcl's lexer positions say nothing to a user
            if text.startswith(f"Couldn't parse {kind}"):
                text = f'{text.split(". Error: ")[0]}; expected {allowed}'
        return text
    finally:
        set_logger_level('rcl', LoggingSeverity.UNSET)  # rcl's warnings of the run itself
    return None


def own_arguments(argv: Sequence[str]) -> list[str]:
    """What rclpy leaves of a command line (executable first): arguments not after --ros-args,
    such as ``-p x:=1`` typed without it, which a node would otherwise ignore in silence."""
    from rclpy.utilities import remove_ros_args

    return remove_ros_args(list(argv))[1:]


class Closeable(Protocol):
    def close(self) -> None: ...


def run_node(executable: str, node_name: str, argv: Sequence[str], stop: threading.Event,
             start: Callable[[Any], Closeable], *,
             bad_input: tuple[type[Exception], ...] = (ParamError,),
             automatic_overrides: bool = True) -> int:
    """Run a node on rclpy until the context shuts down (SIGINT, SIGTERM) or ``stop`` is set.

    The one run loop of sim_node, gantry_node and view_node.

    Args:
        executable: The console script's name, for the command line and messages.
        node_name: The default ROS node name (``-r __node:=`` overrides it).
        argv: The command line after the executable (``--ros-args ...``).
        stop: Set by a signal; the loop ends at the next callback boundary.
        start: Builds the node on the ``RclpyTransport``; what it returns is closed at the
            end, before the transport.
        bad_input: Exceptions of ``start`` that mean an invalid parameter: one line on stderr
            and exit status 2.
        automatic_overrides: Declare every ``-p``/params-file value (see ``RclpyTransport``).

    Returns:
        The exit status: 0 after a signal, 2 for an invalid parameter or command line.
    """
    from growspace_sim.node.rclpy_transport import RclpyTransport

    error = ros_arguments_error([executable, *argv])
    if error is not None:
        print(f'{executable}: invalid ROS arguments: {error}', file=sys.stderr)
        return EXIT_BAD_PARAM
    own = own_arguments([executable, *argv])
    if own in (['-h'], ['--help']):
        print(USAGE.format(executable=executable, namespace=DEFAULT_NAMESPACE))
        return 0
    if own:
        print(f'{executable}: unexpected argument(s) {" ".join(own)!r}: {executable} takes ROS '
              f'arguments only, after --ros-args; did you mean '
              f'`{executable} --ros-args {" ".join(own)}`? ({executable} --help)',
              file=sys.stderr)
        return EXIT_BAD_PARAM
    transport: RclpyTransport | None = None
    node: Closeable | None = None
    try:
        transport = RclpyTransport(node_name, DEFAULT_NAMESPACE, args=[executable, *argv],
                                   automatic_overrides=automatic_overrides,
                                   signal_handlers=False)
        try:
            node = start(transport)
        except bad_input as e:
            print(f'{executable}: invalid parameter: {e}', file=sys.stderr)
            return EXIT_BAD_PARAM
        transport.spin(stop.is_set)
    except Exception as e:  # noqa: BLE001 - the context shut down under us: a signal
        if not stop.is_set():
            raise
        log.debug('%s stopped during start-up: %s', executable, e)
    finally:
        with _closing_watchdog():
            if node is not None:
                node.close()
            if transport is not None:
                transport.close()
    return 0


@contextlib.contextmanager
def _closing_watchdog(timeout_s: float | None = None) -> Iterator[None]:
    """Exit with status 1, every thread's stack on stderr, if the block runs over ``timeout_s``
    (``CLOSE_TIMEOUT_S``). faulthandler's watchdog is a C thread that needs no GIL, so it also
    ends a hang inside native code (rclpy, the middleware)."""
    stderr = sys.__stderr__
    try:
        fileno = stderr.fileno() if stderr is not None else None
    except (OSError, ValueError):  # no file descriptor (an embedding application)
        fileno = None
    if fileno is not None:
        faulthandler.dump_traceback_later(timeout_s or CLOSE_TIMEOUT_S, exit=True, file=stderr)
    try:
        yield
    finally:
        if fileno is not None:
            faulthandler.cancel_dump_traceback_later()


def console_main(run: Callable[[list[str], threading.Event], int],
                 argv: Sequence[str] | None, stopped_line: str = '',
                 logger: logging.Logger = log) -> int:
    """A console script's ``main``: signals only set the stop flag (see the module docstring),
    log lines go to stderr, and ``stopped_line`` is logged to ``logger`` after a signal."""
    stop = threading.Event()

    def on_signal(*_: Any) -> None:
        stop.set()
        # The next one ends the process at once, even while closing hangs in native code.
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_DFL)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    logging.basicConfig(level=logging.INFO, format='[%(levelname)s] [%(name)s]: %(message)s')
    code = run(sys.argv[1:] if argv is None else list(argv), stop)
    if stop.is_set() and stopped_line:
        logger.info(stopped_line)
    return code


def run(argv: Sequence[str], stop: threading.Event) -> int:
    """Run sim_node until the context shuts down (SIGINT, SIGTERM) or ``stop`` is set."""
    def start(transport: Any) -> ChamberNode:
        values, unknown = transport.declare_parameters(params.specs(), params.check_type)
        if unknown:
            transport.logger.warn('params:unknown', f'ignored unknown parameter(s) '
                                  f'{unknown}: not parameters of sim_node (a typo?); '
                                  f'config/growspace.yaml lists them all.')
        cfg, node_params = params.build(values)
        resume = load_resume_point(node_params.resume_path)  # before a new split file opens
        same = bool(resume) and os.path.abspath(node_params.resume_path) == os.path.abspath(
            node_params.record_path)
        recorder = make_recorder(node_params.record_path, node_params.record_max_bytes,
                                 node_params.record_max_duration_s, append=same)
        show = transport.show_parameters  # the challenge parameters follow a reset's switch
        node = ChamberNode(transport, cfg, node_params, recorder, on_reconfigure=lambda c: show(
            {'challenge': c.challenge, 'setting': c.setting}), resume=resume)
        transport.on_parameter_change(node.propose)
        transport.logger.info(
            f'sim_node {transport.resolve("~")}: {node_params.mode} mode, seed {node.seed}'
            + (f', recording to {node_params.record_path}' if recorder else ''))
        return node
    return run_node('sim_node', params.DEFAULT_NODE_NAME, argv, stop, start)


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``sim_node``."""
    return console_main(run, argv, 'sim_node stopped by a signal')


if __name__ == '__main__':
    sys.exit(main())
