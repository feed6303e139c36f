"""The gantry's safety rules, in one place (docs/hardware.md, "Safety model").

Read top to bottom, this module decides whether the machine may move and what every fault
does. The controller (``controller.py``) already clears its target and the lamp power on a
fault it sees; the rules here add what only the node knows (steps, the watchdog, a person's
e-stop) and hold the two latches.

1. A command is refused (nothing sent, the light model unchanged) while
   a. the e-stop is latched: after any e-stop, until a person calls ``gantry/unlock``, whatever
      GRBL reports afterwards (it came back Idle, no alarm, after some e-stops);
   b. the controller is not ready: offline, connecting, a settings mismatch, no report yet;
   c. the controller is in alarm (only a person's ``gantry/unlock`` or ``gantry/home`` leaves
      it), or is stopping a motion the driver did not start (``Run``/``Hold``: see rule 5);
   d. the command is relative (a discrete or continuous action) and the machine position is
      not established: at start-up, after a lost link, a controller restart, an e-stop during
      a move or an alarm that loses steps, until a homing cycle, or a reset or absolute command
      whose move reached its target.
2. Every fault (a lost link, a controller restart, an alarm, an e-stop, a refused line, a jog
   stopped on the machine, a failed or timed-out step) clears the target and turns the lamp off,
   and fails the step in progress with the reason. Nothing moves or lights up until a new
   command (realtime) or a new step or reset (lockstep) arrives.
3. The watchdog (``watchdog_s``) counts from the later of the last accepted command and the end
   of the last move or photo: a move or a step's photo in progress is not silence (the agent
   waits for its answer), a refused command is not a command.
   When it trips, the lamp goes off and the machine holds.
4. Nothing but a person unlocks an alarm or releases the e-stop latch (``gantry/unlock``).
5. Every fault stops the machine in the state GRBL is in, by GRBL's rules (``motion.py``): in
   Jog a jog cancel ``0x85``; in Run (a jog GRBL restarted as a cycle) a feed hold ``!``, then
   once ``Hold:0`` a soft reset ``0x18``; a Hold is reset once stopped. The lamp asked for is 0
   at once; GRBL's spindle output goes off with the reset (or ``M5`` at the next Idle after a
   jog cancel). The position must then be re-established (rule 1d).
"""

from __future__ import annotations

from collections.abc import Callable

from growspace_gantry import grbl
from growspace_gantry.controller import Fault, GrblController, Homed, Log

REESTABLISH = 'home the machine (gantry/home) or send a reset, which places the light'
LATCHED = 'e-stop latched: the driver refuses every command until gantry/unlock is called'


class Safety:
    """The latches and the watchdog of one gantry.

    Args:
        controller: the machine.
        log: the node's log (warnings throttled by key).
        fail_step: answers the step in progress (if any) as failed with a reason.
        watchdog_s: seconds of silence before the lamp goes off (0 = never).
        now: the current time [s].
    """

    def __init__(self, controller: GrblController, log: Log, fail_step: Callable[[str], None],
                 watchdog_s: float, now: float) -> None:
        self.controller = controller
        self.log = log
        self.fail_step = fail_step
        self.watchdog_s = watchdog_s
        self.estop_latched = False
        self.position_known = False
        self.position_doubt = 'the machine position is not established since start-up'
        self.watchdog_tripped = False
        self._last_activity = now
        self._placing = False  # the current move is a reset or an absolute command

    # --- rule 1: may this command move the machine? ------------------------------------------

    def refusal(self, relative: bool) -> str:
        """Why a command may not be sent now ('' if it may)."""
        c = self.controller
        if self.estop_latched:
            return LATCHED
        if c.fault:
            return f'fault: {c.fault}'
        if c.phase != 'ready':
            return c.failure or f'the controller is {c.phase}'
        if c.alarm is not None:
            return f'{grbl.alarm_text(c.alarm)}; a person must call gantry/unlock or gantry/home'
        if c.motion.halting:
            return f'stopping a motion the driver did not start (controller: {c.state}): feed ' \
                f'hold, then a soft reset once stopped'
        if c.status is None or c.position is None:
            return 'no status report with a machine position from the controller yet'
        if relative and not self.position_known:
            return f'{self.position_doubt}; it must be re-established before a relative ' \
                f'action: {REESTABLISH}'
        return ''

    def accepted(self, now: float, placing: bool) -> None:
        """A command was sent: it feeds the watchdog; an absolute one re-establishes the
        position once reached."""
        self._last_activity = now
        self.watchdog_tripped = False
        self._placing = placing

    # --- rule 2: every fault ------------------------------------------------------------------

    def fault(self, reason: str, position_lost: bool = False) -> None:
        """Stop: no target, lamp off, the step in progress failed with ``reason``."""
        self.controller.safe_stop()
        self._placing = False
        if position_lost and self.position_known:
            self.position_known = False
            self.position_doubt = f'the machine position is lost ({reason})'
            self.log.warn('position', f'gantry: {self.position_doubt}; relative actions are '
                      f'refused until it is re-established: {REESTABLISH}.')
        self.fail_step(reason)

    def estop(self, source: str) -> None:
        """Feed hold, lamp off, soft reset, and the latch."""
        self.estop_latched = True
        moving = self.controller.estop()
        self.log.warn('estop', f'gantry: EMERGENCY STOP from {source}: feed hold, lamp off, soft '
                  f'reset. {LATCHED}, whatever the controller reports.')
        self.fault('emergency stop', position_lost=moving)

    # --- rule 4: only a person unlocks ----------------------------------------------------------

    def unlock(self) -> str:
        """A person's gantry/unlock: releases the e-stop latch, and sends ``$X`` in alarm.

        Returns:
            '' (done) or why nothing was done.
        """
        released, self.estop_latched = self.estop_latched, False
        if released:
            self.log.info('gantry: e-stop latch released by gantry/unlock; nothing moves until '
                          'a new command')
            if self.controller.alarm is None:
                return ''
        return self.controller.unlock()

    def home(self) -> str:
        """A person's gantry/home (``$H``); not while the e-stop is latched."""
        if self.estop_latched:
            return f'{LATCHED} (then home)'
        return self.controller.home()

    def tick(self, now: float, events: list, photographing: bool = False) -> None:
        """Apply rules 2 and 3 to one poll of the controller (``photographing``: a step's
        photo is under way)."""
        c = self.controller
        for event in events:
            if isinstance(event, Fault):
                self.fault(event.reason, event.position_lost)
            elif isinstance(event, Homed):
                self._established('homing finished')
        if self._placing and c.reached():
            self._placing = False
            self._established('a reset or absolute command reached its target')
        if c.busy or photographing:
            self._last_activity = now  # a move or photo in progress is not a silent agent
        # --- rule 3: the watchdog
        if self.watchdog_s and c.lamp_s > 0 and not self.watchdog_tripped \
                and now - self._last_activity > self.watchdog_s:
            self.watchdog_tripped = True
            self.fault(f'watchdog: no command for {self.watchdog_s:g} s')
            self.log.warn('watchdog', f'gantry: no command for {self.watchdog_s:g} s since the '
                      f'last move ended (watchdog_s): lamp off, holding; the next command '
                      f'turns it on again.')

    def _established(self, how: str) -> None:
        if not self.position_known:
            self.position_known = True
            self.log.info(f'gantry: machine position established ({how}).')
