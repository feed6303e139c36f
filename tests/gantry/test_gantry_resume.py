"""gantry_node restarted with ``resume_path`` (issue 31 item 4): it goes on with the recorded
episode (its reset_id, step count, last step_id) and places the episode's first action
absolutely from the light the recording says it last reached, though its position is not
established after the restart. Against the GRBL emulator on a pseudo-terminal."""

from __future__ import annotations

import pytest

from growspace_gantry.resume import GantryResume, load, ResumeError
from growspace_sim.core.config import SimConfig
from growspace_sim.ros import convert, types
from growspace_sim.simulation import Simulation
from test_gantry_node import jogs, Rig

RESET_ID = 1048577
LIGHT = (0.3, 0.25, 0.2, 0.0)  # where the recorded episode's last step left the light


def _resumed(tmp_path) -> Rig:
    point = GantryResume(SimConfig(), seed=7, reset_id=RESET_ID, last_step_id=5, steps=5,
                         light=LIGHT, over=False)
    return Rig(tmp_path, resume=point)


def _action(step_id: int, action: int):
    return types.new(types.LIGHT_COMMAND, step_id=step_id, mode=convert.MODE_DISCRETE,
                     action=action)


def test_a_resumed_gantry_keeps_the_episode_and_places_its_first_action_from_the_record(
        tmp_path) -> None:
    rig = _resumed(tmp_path)
    try:
        rig.ready()
        assert jogs(rig.grbl) == []  # nothing moves at start-up
        assert not rig.node.safety.position_known
        duplicate = rig.command(5, mode=convert.MODE_DISCRETE, action=1)
        assert (duplicate.reset_id, duplicate.step) == (RESET_ID, 5) and duplicate.info
        answer = rig.command(6, mode=convert.MODE_DISCRETE, action=1)
        assert answer.info == '' and (answer.reset_id, answer.step) == (RESET_ID, 6)
        expected = Simulation(SimConfig())
        expected.reset(seed=7)
        x, z, width, radius = LIGHT
        expected.place_light(x=x, z=z, width=width, radius=radius)
        convert.apply_command(expected, _action(6, 1))
        reached = rig.transport.messages('light/state')[-1]
        assert abs(reached.x - expected.chamber.light.x) < 1e-3, (reached.x, LIGHT)
        assert rig.node.safety.position_known  # the absolute move re-established it
    finally:
        rig.close()


def test_without_resume_a_relative_action_after_start_up_is_refused(tmp_path) -> None:
    rig = Rig(tmp_path)
    try:
        rig.ready()
        answer = rig.command(1, mode=convert.MODE_DISCRETE, action=1)
        assert 'must be re-established' in answer.info and answer.step == 0
    finally:
        rig.close()


def test_a_resume_path_that_does_not_exist_is_named(tmp_path) -> None:
    with pytest.raises(ResumeError, match=r"resume_path = '.*nothing' does not exist"):
        load(str(tmp_path / 'nothing'))


def test_the_redo_of_a_failed_step_moves_from_where_the_last_answered_step_left_the_light(
        tmp_path) -> None:
    """A step that failed after its move (here superseded in its growth period, as when a
    resumed runner redoes it) is redone with the same action: the light goes where that
    action takes it from the last answered step, not one action further."""
    from test_gantry_growth import step_phase
    from test_gantry_safety import place

    rig = Rig(tmp_path, growth_s=60.0, watchdog_s=0.0)
    try:
        rig.ready()
        place(rig)
        rig.transport.inject('light/command', _action(1, 1))
        assert rig.run_until(lambda: step_phase(rig) == 'growing')  # moved, then failed:
        once = rig.node.sim.chamber.light.x
        rig.transport.inject('light/command', _action(2, 1))  # the redo supersedes it
        assert rig.run_until(lambda: any(r.step_id == 1 for r in rig.results()))
        assert 'superseded' in next(r for r in rig.results() if r.step_id == 1).info
        assert rig.node.sim.chamber.light.x == pytest.approx(once)
        assert rig.run_until(lambda: step_phase(rig) == 'growing' and rig.controller.reached())
    finally:
        rig.close()


class DiskFull:
    """A recorder whose disk fills up at the first message (as ``McapRecorder`` reports an I/O
    error: the write raises and ``error`` names it from then on)."""

    error: str | None = None

    def add_channel(self, *args) -> int:
        return 0

    def add_metadata(self, *args) -> None:
        pass

    def write_many(self, records) -> None:
        self.error = 'Cannot write recording run_0.mcap: No space left on device'
        raise OSError(28, 'No space left on device')

    def flush(self, sync: bool = False) -> None:
        pass

    def close(self) -> None:
        pass


def test_a_recording_that_stopped_refuses_every_command_and_reset(tmp_path) -> None:
    # Issue 31: nothing lost. A step the recording cannot hold would be a step no resume can
    # find; so once the recorder has stopped, nothing moves until a person restarts the node.
    rig = Rig(tmp_path, recorder=DiskFull())
    try:
        rig.ready()
        reset = types.new(types.RESET_REQUEST, reset_id=RESET_ID, has_seed=True, seed=3)
        rig.transport.inject('reset', reset)
        assert rig.run_until(lambda: rig.results()), rig.transport.warnings
        assert 'recording stopped' in rig.results()[-1].info
        assert 'No space left on device' in rig.results()[-1].info
        answer = rig.command(1, mode=convert.MODE_BEAM, x=0.5, width=0.2)
        assert 'recording stopped' in answer.info and 'resume_path' in answer.info
        assert jogs(rig.grbl) == []  # nothing moved
        assert any('every command is refused' in w for w in rig.transport.warnings)
    finally:
        rig.close()
