"""``gantry/status``: what is true of the machine, as a diagnostic_msgs/DiagnosticArray.

Level ERROR (2) for a latched e-stop, an alarm, a settings fault or a lost link; WARN (1) while
connecting, before the first status report, while the position is not established or after
the watchdog tripped; OK (0) only with a report in hand and nothing of the above. ``lamp_s`` is
the S the firmware reports (its status ``FS`` field), "unknown" while no report says so;
``photo_light`` is the last ``M8``/``M9`` GRBL accepted ("unknown" after a reset until the next),
``photo`` where a step's photo is (empty without a camera). ``step`` is the lockstep step's
phase (``moving``, ``growing``, ``growing, night: lamp off``, ``photo``, or empty between steps),
``growth_left_s`` the lit seconds of its growth period still to come and ``growth_ends_in_s``
the wall seconds to its end (nights included); ``lights`` whether the photoperiod lets the lamp
be lit now (``on``, ``off (night)``).
"""

from __future__ import annotations

from typing import Any

from growspace_gantry import grbl
from growspace_sim.ros import convert, types

DIAGNOSTICS = types.DIAGNOSTICS
OK, WARN, ERROR = 0, 1, 2


def level_and_message(node: Any) -> tuple[int, str]:
    """The diagnostic level and its one-line message, worst first."""
    c, safety = node.controller, node.safety
    if safety.estop_latched:
        return ERROR, f'e-stop latched: every command is refused until gantry/unlock ' \
            f'(controller: {c.state})'
    if c.fault:
        return ERROR, f'fault: {c.fault}'
    if c.alarm is not None:
        return ERROR, grbl.alarm_text(c.alarm)
    if c.link is None:
        return ERROR, f'offline: {c.failure}' if c.failure else 'offline'
    if c.phase != 'ready' or c.status is None:
        return WARN, f'{c.state}: waiting for the controller'
    if not safety.position_known:
        return WARN, f'{c.state}; {safety.position_doubt}: it must be re-established before ' \
            f'relative actions (home, or a reset that places the light)'
    if safety.watchdog_tripped:
        return WARN, f'{c.state}; watchdog tripped: lamp off until the next command'
    return OK, c.state


def step_values(node: Any) -> dict[str, str]:
    """The step's phase, its growth time left, and the photoperiod now."""
    grow = node.step_time
    lit_left, wall_left = grow.left()
    if node.pending is not None:
        phase = 'moving'
    else:
        phase = grow.phase() or ('photo' if node.photo is not None and node.photo.busy else '')
    return {'step': phase, 'growth_left_s': f'{lit_left:.1f}',
            'growth_ends_in_s': f'{wall_left:.1f}',
            'lights': 'on' if grow.lamp_s(1.0) else 'off (night)'}


def diagnostics(node: Any) -> Any:
    """The ``gantry/status`` message of a ``GantryNode`` now."""
    c = node.controller
    level, message = level_and_message(node)
    pos = c.position or {}
    lamp = c.lamp_reported
    suppressed = getattr(node.log, 'suppressed', None)
    values = {
        'state': c.state, 'link': 'connected' if c.link is not None else 'offline',
        'grbl_version': c.version, 'alarm': '' if c.alarm is None else str(c.alarm),
        'mpos_x_mm': f'{pos.get("X", float("nan")):.3f}',
        'mpos_y_mm': f'{pos.get("Y", float("nan")):.3f}',
        'mpos_z_mm': f'{pos.get("Z", float("nan")):.3f}',
        'rx_buffer_used_bytes': str(c.counter.used),
        'lines_in_flight': str(c.counter.pending),
        'planner_free_blocks': '' if c.status is None or c.status.planner_free is None
        else str(c.status.planner_free),
        'lamp_s': 'unknown' if lamp is None else f'{lamp:g}',
        'lamp_requested_s': f'{c.lamp_s:g}',
        'estop_latched': str(node.safety.estop_latched).lower(),
        'position_established': str(node.safety.position_known).lower(),
        'watchdog_tripped': str(node.safety.watchdog_tripped).lower(),
        'photo': '' if node.photo is None else node.photo.phase,
        'photo_light': '' if not c.has_photo_light else
        {True: 'on', False: 'off', None: 'unknown'}[c.photo_light_accepted],
        **step_values(node),
        'last_failure': c.failure or '',
        'warnings_suppressed': '' if suppressed is None else str(suppressed),
    }
    kv = [types.new('diagnostic_msgs/msg/KeyValue', key=k, value=v) for k, v in values.items()]
    status = types.new('diagnostic_msgs/msg/DiagnosticStatus', level=level,
                       name=f'{node.transport.resolve("~")}: GRBL controller',
                       message=message, hardware_id=node.params.port, values=kv)
    return types.new(DIAGNOSTICS, header=convert.header(node.transport.now_ns(),
                                                        node.params.frame_id),
                     status=[status])
