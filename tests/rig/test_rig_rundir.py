"""The run directory and its journal (pure, files only), the progress line, the CLI's errors."""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from growspace_sim.recording import RecordingError, repair, SplitRecorder, wait_until_free
from growspace_sim.rig.cli import main as rig_main
from growspace_sim.rig.rundir import (
    format_progress, read_journal, RunDir, RunDirError, RunSettings)
from growspace_sim.rig.faults import PAUSE_ENV

UTC = dt.UTC


def _journal_steps(run: RunDir, episode: int, steps: range) -> None:
    for step in steps:
        run.append('intent', episode=episode, step=step, step_id=step, action=1)
        run.append('step', episode=episode, step=step, step_id=step, action=1, reward=0.5,
                   terminated=False, truncated=step == 50)


def test_create_writes_settings_once_and_never_reuses_a_directory(tmp_path):
    run = RunDir.create(tmp_path / 'run', RunSettings(episodes=3, seed=10))
    saved = json.loads((tmp_path / 'run' / 'run.json').read_text())
    assert saved['episodes'] == 3 and saved['created'].endswith('Z')
    assert saved['namespace'].startswith('/growspace_rig_')  # fixed for the run's life
    assert RunDir(tmp_path / 'run').settings == run.settings
    with pytest.raises(RunDirError, match='exists already; `growspace-rig resume'):
        RunDir.create(tmp_path / 'run', RunSettings())
    with pytest.raises(RunDirError, match='not a run directory'):
        RunDir(tmp_path)


@pytest.mark.parametrize('field, value, allowed', [
    ('episodes', 0, 'an integer >= 1'), ('policy', 'greedy', 'one of oracle'),
    ('chamber', 'rig', 'one of sim, attach'), ('step_period_s', -1.0, '>= 0'),
    ('step_timeout_s', 0.0, '> 0'), ('seed', -2, 'an integer >= 0'),
    ('policy_path', '', 'needs the path')])
def test_bad_settings_name_the_field_value_and_what_is_allowed(field, value, allowed):
    base = RunSettings(policy='replay', policy_path='x.mcap') if field == 'policy_path' \
        else RunSettings()
    values = {**dataclasses.asdict(base), field: value}
    with pytest.raises(RunDirError, match=rf'{field} = {value!r} is not allowed; .*{allowed}'):
        RunSettings(**values)


def test_journal_holds_completed_steps_and_the_one_in_progress(tmp_path):
    run = RunDir.create(tmp_path / 'run', RunSettings(episodes=2))
    run.append('reset', episode=0, reset_id=11, seed=0)
    _journal_steps(run, 0, range(1, 4))
    run.append('intent', episode=0, step=4, step_id=4, action=2)
    state = read_journal(run.journal_path)
    assert state == run.state  # what is on disk is what the runner believes
    assert [s.step for s in state.current.steps] == [1, 2, 3]
    assert state.pending['step'] == 4 and state.steps_done == 3 and state.duplicated == 0


def test_a_line_cut_short_by_a_crash_is_no_event_and_is_cut_before_the_next(tmp_path):
    run = RunDir.create(tmp_path / 'run', RunSettings())
    run.append('reset', episode=0, reset_id=11, seed=0)
    _journal_steps(run, 0, range(1, 3))
    with open(run.journal_path, 'a') as stream:
        stream.write('{"event":"step","episode":0,"st')  # the crash came mid-write
    again = RunDir(tmp_path / 'run')
    assert len(again.state.current.steps) == 2 and not again.state.torn
    again.append('note', text='after the crash')
    assert read_journal(again.journal_path).events == again.state.events


def test_a_damaged_line_inside_the_journal_is_an_error_naming_it(tmp_path):
    run = RunDir.create(tmp_path / 'run', RunSettings())
    run.append('reset', episode=0, reset_id=11, seed=0)
    text = run.journal_path.read_text()
    run.journal_path.write_text('garbage\n' + text)
    with pytest.raises(RunDirError, match=r'journal.jsonl:1: not a journal event'):
        RunDir(tmp_path / 'run')


def test_a_step_journaled_twice_is_counted_not_hidden(tmp_path):
    run = RunDir.create(tmp_path / 'run', RunSettings())
    run.append('reset', episode=0, reset_id=11, seed=0)
    _journal_steps(run, 0, range(1, 3))
    _journal_steps(run, 0, range(2, 3))
    assert read_journal(run.journal_path).duplicated == 1


_JOURNAL_TWO_EPISODES = """
import sys
from growspace_sim.rig.rundir import RunDir
run = RunDir(sys.argv[1])
for episode, steps in ((0, 50), (1, 5)):
    run.append('reset', episode=episode, reset_id=11 + episode, seed=episode)
    for step in range(1, steps + 1):
        run.append('intent', episode=episode, step=step, step_id=step, action=1)
        run.append('step', episode=episode, step=step, step_id=step, action=1, reward=0.5,
                   terminated=False, truncated=step == 50)
"""


@pytest.mark.parametrize('stage', ['intent', 'step'])
def test_the_fault_injection_pause_stops_the_process_at_that_line_of_the_runs_nth_step(
        tmp_path, stage):
    """PAUSE_ENV (the soak's and tests' hook): step 52 of the run is episode 2's step 2."""
    RunDir.create(tmp_path / 'run', RunSettings(episodes=2))
    proc = subprocess.Popen([sys.executable, '-c', _JOURNAL_TWO_EPISODES, str(tmp_path / 'run')],
                            env=dict(os.environ, **{PAUSE_ENV: f'{stage}:52'}))
    try:
        stopped = os.waitid(os.P_PID, proc.pid, os.WSTOPPED | os.WEXITED | os.WNOWAIT)
        assert stopped.si_code == os.CLD_STOPPED
        last = json.loads((tmp_path / 'run' / 'journal.jsonl').read_text().splitlines()[-1])
        assert (last['event'], last['episode'], last['step']) == (stage, 1, 2)
    finally:
        proc.kill()
        proc.wait()


@pytest.mark.parametrize('value', ['52', 'reset:3', 'step:0', 'step:x', 'step:\u00b2'])
def test_a_bad_fault_injection_pause_is_refused_naming_it(tmp_path, monkeypatch, value):
    """Before a run directory is made; an existing one still opens (status reads it), and
    refuses its first journal line."""
    RunDir.create(tmp_path / 'old', RunSettings())
    monkeypatch.setenv(PAUSE_ENV, value)
    refused = rf"{PAUSE_ENV}='{value}' is not allowed; intent:N or step:N \(N >= 1\)"
    with pytest.raises(RunDirError, match=refused):
        RunDir.create(tmp_path / 'new', RunSettings())
    assert not (tmp_path / 'new').exists()
    old = RunDir(tmp_path / 'old')
    with pytest.raises(RunDirError, match=refused):
        old.append('reset', episode=0, reset_id=11, seed=0)
    assert not old.journal_path.exists()


def test_progress_line_says_step_k_of_n_next_step_time_and_eta(tmp_path):
    run = RunDir.create(tmp_path / 'run', RunSettings(episodes=2, step_period_s=3600.0))
    run.append('reset', episode=0, reset_id=11, seed=0)
    _journal_steps(run, 0, range(1, 18))
    now = dt.datetime(2026, 11, 28, 12, 0, tzinfo=UTC)
    line = format_progress(run.settings, run.state, 50, now, now + dt.timedelta(hours=1), 60.0)
    # 83 steps left: the next at 13:00, then 82 more an hour apart, the last taking 60 s.
    assert line == ('episode 1/2 step 17/50 | 17/100 steps done | next step 13:00:00 UTC | '
                    'ETA 2026-12-01 23:01:00 UTC')
    _journal_steps(run, 0, range(18, 51))
    run.append('reset', episode=1, reset_id=12, seed=1)
    _journal_steps(run, 1, range(1, 51))
    assert format_progress(run.settings, run.state, 50, now, None, 60.0) == \
        'episode 2/2 step 50/50 | 100/100 steps done | finished'


def test_cli_errors_name_the_argument_value_and_what_is_allowed(tmp_path, capsys):
    assert rig_main(['run', str(tmp_path / 'a'), '--episodes', '0']) == 2
    assert capsys.readouterr().err.strip() == ('growspace-rig: error: argument --episodes: '
                                               'episodes = 0 is not allowed; an integer >= 1.')
    assert rig_main(['run', str(tmp_path / 'b'), '--chamber', 'attach']) == 2
    assert 'argument --namespace' in capsys.readouterr().err
    assert rig_main(['resume', str(tmp_path / 'none')]) == 2
    assert 'is not a run directory' in capsys.readouterr().err
    assert rig_main(['run', str(tmp_path / 'c'), '--policy', 'replay', '--policy-path',
                     str(tmp_path / 'missing.mcap')]) == 2
    assert "argument --policy-path: '" in capsys.readouterr().err
    assert not any((tmp_path / name).exists() for name in 'abc')


def test_status_reads_the_journal_without_a_chamber(tmp_path, capsys):
    run = RunDir.create(tmp_path / 'run', RunSettings(episodes=1))
    run.append('reset', episode=0, reset_id=11, seed=0)
    _journal_steps(run, 0, range(1, 6))
    assert rig_main(['status', str(tmp_path / 'run')]) == 1  # not finished
    assert 'episode 1/1 step 5/50 | 5/50 steps done' in capsys.readouterr().out


def test_a_split_recording_being_written_is_locked_against_a_second_writer(tmp_path):
    with SplitRecorder(tmp_path / 'rec'):
        with pytest.raises(RecordingError, match='being recorded by another process'):
            SplitRecorder(tmp_path / 'rec', append=True)
        with pytest.raises(RecordingError, match='being recorded by another process'):
            repair(tmp_path / 'rec')
        assert not wait_until_free(tmp_path / 'rec', 0.0)
    assert wait_until_free(tmp_path / 'rec', 0.0)


class _FakeRig:
    """A chamber without ROS for the loop's logic: its own twin answers; chosen ids refused."""

    recording = None
    simulated = False

    def __init__(self, refuse: set[int]) -> None:
        from growspace_sim.core.config import SimConfig
        from growspace_sim.rig.policies import Twin

        self.twin = Twin(SimConfig())
        self.refuse = refuse
        self.sent: list[int] = []
        self.last_id = 0

    def prepare(self):
        return {}

    def start(self, resume: bool) -> None:
        pass

    def reset(self, reset_id: int, seed: int):
        from growspace_sim.rig.runner import Answer

        self.twin.reset(0, seed)
        return Answer('', observation=self.twin.sim.observe())

    def step(self, reset_id: int, step_id: int, action: int):
        from growspace_sim.rig.runner import Answer

        self.sent.append(step_id)
        if step_id in self.refuse:  # what gantry_node answers in alarm
            return Answer('error: gantry not ready: the controller is in alarm (ALARM:1)',
                          step=self.twin.chamber.steps)
        if step_id <= self.last_id:  # the lockstep rule of sim_node and gantry_node
            return Answer(f'error: step_id = {step_id} is a duplicate or late command',
                          step=self.twin.chamber.steps)
        self.last_id = step_id
        outcome = self.twin.step(action)
        return Answer('', outcome.reward, False, outcome.truncated, self.twin.chamber.steps,
                      self.twin.sim.observe())

    def close(self) -> None:
        pass


def test_a_refused_step_asks_for_a_person_and_is_retried_with_a_new_step_id(tmp_path):
    from growspace_sim.rig.runner import Runner

    run = RunDir.create(tmp_path / 'run', RunSettings(policy='random', chamber='attach',
                                                      namespace='/rig', retry_period_s=30.0))
    chamber, said, slept = _FakeRig(refuse={3, 4}), [], []
    Runner(run, chamber, say=said.append, sleep=slept.append).run()
    assert slept == [30.0, 30.0]  # waited twice, for a person, then went on
    waiting = [line for line in said if line.startswith('WAITING FOR A PERSON')]
    assert len(waiting) == 2 and 'ALARM:1' in waiting[0] and 'gantry/unlock' in waiting[0]
    assert chamber.sent[:5] == [1, 2, 3, 4, 5]  # never an id twice
    episode = read_journal(run.journal_path).episodes[0]
    assert [s.step for s in episode.steps] == list(range(1, 51))
    assert episode.steps[2].step_id == 5 and episode.steps[-1].truncated
    assert 'finished' in said[-1]


@pytest.mark.parametrize('chamber_did_it', [True, False])
def test_resume_on_an_attached_chamber_never_repeats_the_step_in_progress(tmp_path,
                                                                          chamber_did_it):
    """The runner died after journaling step 4's intent; the chamber (alive) had done it, or
    never got it. Resent with its own step_id: done once either way."""
    from growspace_sim.rig.policies import RandomPolicy
    from growspace_sim.rig.runner import reset_id_of, Runner

    run = RunDir.create(tmp_path / 'run', RunSettings(policy='random', chamber='attach',
                                                      namespace='/rig', seed=4))
    chamber, policy = _FakeRig(refuse=set()), RandomPolicy(4)
    chamber.reset(reset_id_of(0), 4)
    run.append('reset', episode=0, reset_id=reset_id_of(0), seed=4)
    chamber.twin.episode = 0
    for step in range(1, 5):
        action = policy.act(None, chamber.twin)
        run.append('intent', episode=0, step=step, step_id=step, action=action)
        if step < 4 or chamber_did_it:
            answer = chamber.step(reset_id_of(0), step, action)
        if step < 4:
            run.append('step', episode=0, step=step, step_id=step, action=action,
                       reward=answer.reward, terminated=False, truncated=False)
    resumed = RunDir(tmp_path / 'run')
    Runner(resumed, chamber, say=lambda line: None, sleep=lambda s: None).run()
    assert chamber.twin.chamber.steps == 50  # the chamber stepped 50 times, no more
    state = read_journal(resumed.journal_path)
    assert [s.step for s in state.episodes[0].steps] == list(range(1, 51))
    assert state.duplicated == 0
    lost = [s.step for s in state.episodes[0].steps if s.reward != s.reward]  # NaN
    assert lost == ([4] if chamber_did_it else [])


def test_the_step_period_holds_across_a_resume_and_a_schedule_can_hold_a_step(tmp_path):
    from growspace_sim.rig.runner import reset_id_of, Runner

    run = RunDir.create(tmp_path / 'run', RunSettings(policy='random', chamber='attach',
                                                      namespace='/rig', step_period_s=3600.0))
    chamber = _FakeRig(refuse=set())
    chamber.reset(reset_id_of(0), 0)
    run.append('reset', episode=0, reset_id=reset_id_of(0), seed=0)
    # A step begun at 10:00 and answered; the runner then died. Resumed at 10:10.
    with open(run.journal_path, 'a') as stream:
        stream.write('{"event":"intent","t":"2026-11-28T10:00:00Z","episode":0,"step":1,'
                     '"step_id":1,"action":0}\n')
    chamber.step(reset_id_of(0), 1, 0)
    run = RunDir(tmp_path / 'run')
    clock = [dt.datetime(2026, 11, 28, 10, 10, tzinfo=UTC)]
    slept: list[float] = []

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        clock[0] += dt.timedelta(seconds=seconds)

    def lights_on_at_six(at: dt.datetime) -> dt.datetime:  # a night from 20:00 to 06:00
        if at.hour >= 20:
            return (at + dt.timedelta(days=1)).replace(hour=6, minute=0, second=0)
        return at

    said: list[str] = []
    runner = Runner(run, chamber, say=said.append, clock=lambda: clock[0], sleep=sleep,
                    not_before=lights_on_at_six)
    runner.run()
    assert slept[0] == 50 * 60  # step 2 one hour after step 1 began, not at once
    assert slept[1:9] == [3600.0] * 8  # then one an hour: 12:00, ..., 19:00
    night = [line for line in said if line.startswith('the schedule holds')]
    assert night and night[0].endswith('06:00:00 UTC')


def test_the_replay_policy_plays_a_recordings_actions_step_by_step(tmp_path):
    from pathlib import Path

    from growspace_sim.replay import Bag, read_episodes
    from growspace_sim.rig.runner import Runner

    sample = Path(__file__).resolve().parents[2] / 'bags' / 'oracle_control_easy.mcap'
    with Bag(sample) as bag:
        recorded = read_episodes(bag)[0]
        seed = recorded.seed
    run = RunDir.create(tmp_path / 'run', RunSettings(
        policy='replay', policy_path=str(sample), chamber='attach', namespace='/rig',
        seed=seed))
    Runner(run, _FakeRig(refuse=set()), say=lambda line: None, sleep=lambda s: None).run()
    episode = read_journal(run.journal_path).episodes[0]
    assert [s.action for s in episode.steps] == \
        [int(r.commands[0].action) for r in recorded.stepped]
    # The fake chamber is the simulator: the recorded rewards come back bit for bit.
    assert [s.reward for s in episode.steps] == [float(r.result.reward) for r in recorded.stepped]


def test_the_runners_photoperiod_holds_a_step_until_lights_on_and_is_checked_when_created():
    from growspace_sim.rig.schedule import hold_for, next_lit

    settings = RunSettings(chamber='sim', lights_on='06:00', lights_off='20:00',
                           utc_offset_h=1.0)  # local standard time = UTC + 1 h
    hold = hold_for(settings.photoperiod)
    day = dt.datetime(2026, 11, 28, 9, 30, tzinfo=UTC)  # 10:30 local: lit
    assert hold(day) == day
    night = dt.datetime(2026, 11, 28, 19, 30, tzinfo=UTC)  # 20:30 local: held
    assert hold(night) == dt.datetime(2026, 11, 29, 5, 0, tzinfo=UTC)  # 06:00 local
    crossing = RunSettings(chamber='sim', lights_on='22:00', lights_off='04:00').photoperiod
    noon = dt.datetime(2026, 11, 28, 12, 0, tzinfo=UTC)
    assert next_lit(crossing, noon) == dt.datetime(2026, 11, 28, 22, 0, tzinfo=UTC)
    assert hold_for(RunSettings().photoperiod) is None  # no night: nothing held
    with pytest.raises(RunDirError) as error:
        RunSettings(lights_on='06:00')
    assert error.value.field == 'lights_on' and 'give both' in str(error.value)


class _StartingRig(_FakeRig):
    """Refuses its first ``refusals`` resets with ``info``, as gantry_node does while starting."""

    def __init__(self, refusals: int, info: str, simulated: bool = False) -> None:
        super().__init__(refuse=set())
        self.refusals, self.info, self.simulated = refusals, info, simulated
        self.resets: list[int] = []

    def reset(self, reset_id: int, seed: int):
        from growspace_sim.rig.runner import Answer

        self.resets.append(reset_id)
        if len(self.resets) <= self.refusals:
            return Answer(self.info, observation=np.full((2, 2, 3), 7, np.uint8))  # not kept
        return super().reset(reset_id, seed)


def test_a_reset_refused_as_not_ready_waits_for_a_person_then_goes_again(tmp_path):
    """A gantry still starting (or in alarm) refuses the first reset: the runner waits and sends
    the same reset again, as it does a refused step, instead of ending the run."""
    from growspace_sim.rig.runner import reset_id_of, Runner

    run = RunDir.create(tmp_path / 'run', RunSettings(policy='random', chamber='attach',
                                                      namespace='/rig', retry_period_s=30.0))
    chamber = _StartingRig(2, 'error: gantry not ready: the controller is booting')
    said, slept = [], []
    runner = Runner(run, chamber, say=said.append, sleep=slept.append)
    observations = []  # what the policy is given at each step
    real_step = chamber.step

    def step(*args):
        observations.append(runner.observation)
        return real_step(*args)

    chamber.step = step
    runner.run()
    assert chamber.resets == [reset_id_of(0)] * 3 and slept == [30.0, 30.0]
    assert observations[0].shape != (2, 2, 3)  # the accepted reset's observation
    waiting = [line for line in said if line.startswith('WAITING FOR A PERSON')]
    assert len(waiting) == 2 and 'the reset of episode 1' in waiting[0]
    assert 'the controller is booting' in waiting[0]
    state = read_journal(run.journal_path)
    assert len(state.episodes) == 1 and state.episodes[0].reset_id == reset_id_of(0)
    assert [s.step for s in state.episodes[0].steps] == list(range(1, 51))
    notes = [e for e in map(json.loads, open(run.journal_path)) if e['event'] == 'note']
    assert len(notes) == 2 and 'the reset of episode 1' in notes[0]['text']


@pytest.mark.parametrize('info, simulated', [
    ('error: light x = 1.2 m is outside its travel [0.0, 1.0]', False),  # refused again
    ('error: gantry not ready: the controller is booting', True),  # a simulator never is
])
def test_a_reset_refused_for_good_ends_the_run_at_once(tmp_path, info, simulated):
    from growspace_sim.rig.runner import Runner, RunnerError

    run = RunDir.create(tmp_path / 'run', RunSettings(policy='random', chamber='attach',
                                                      namespace='/rig', retry_period_s=30.0))
    chamber, slept = _StartingRig(1, info, simulated), []
    with pytest.raises(RunnerError, match='the chamber refused the reset of episode 1 '
                       r'\(reset_id \d+, seed \d+\): ' + re.escape(info)):
        Runner(run, chamber, say=lambda line: None, sleep=slept.append).run()
    assert len(chamber.resets) == 1 and slept == []
    assert read_journal(run.journal_path).episodes == []
