"""``growspace-rig`` on sim_node: killed mid-episode (SIGKILL), resumed, every step exactly once.

The runner starts its own sim_node (recording into the run directory, split by size); the test
kills the runner with SIGKILL in the middle of an episode, optionally damages what a crash can
damage, and resumes it. The finished run must hold every step of every episode exactly once, in
the journal and in the recording, with the rewards of an uninterrupted in-process run bit for
bit.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import signal
import subprocess
import sys

import numpy as np
import pytest

from growspace_sim.agents import OracleAgent, play_episodes
from growspace_sim.envs.env import GrowSpaceEnv
from growspace_sim.recording import split_files
from growspace_sim.replay import Bag, read_episodes, resimulate
from growspace_sim.rig.faults import PAUSE_ENV
from growspace_sim.rig.rundir import read_journal
from growspace_sim.rig.runner import recorded_episodes, reset_id_of
from waiting import wait_until

pytestmark = pytest.mark.slow  # each test runs sim_node and the runner as processes

SEED, EPISODES = 3, 2
KILL_AFTER_STEPS = 20  # journaled steps before the SIGKILL: inside the first episode
TIMEOUT_S = 300  # a whole run on a loaded 2-core machine, generous


def _rig(*args: str) -> list[str]:
    return [sys.executable, '-m', 'growspace_sim.rig.cli', *args]


def _steps_journaled(run: Path) -> int:
    try:
        return (run / 'journal.jsonl').read_text().count('"event":"step"')
    except FileNotFoundError:
        return 0


def _start_and_kill(run: Path) -> None:
    """Run, SIGKILLed once its 20th step is journaled (it stops itself there: PAUSE_ENV)."""
    proc = subprocess.Popen(_rig('run', str(run), '--episodes', str(EPISODES), '--seed',
                                 str(SEED), '--record-max-bytes', '200000'),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, **{PAUSE_ENV: f'step:{KILL_AFTER_STEPS}'}))
    try:
        stopped = wait_until(lambda: os.waitid(os.P_PID, proc.pid, os.WSTOPPED | os.WEXITED
                                               | os.WNOWAIT | os.WNOHANG), TIMEOUT_S,
                             'the runner stops itself after its 20th step')
        assert stopped.si_code == os.CLD_STOPPED, 'the runner ended before its 20th step'
        assert _steps_journaled(run) == KILL_AFTER_STEPS
    finally:
        proc.send_signal(signal.SIGKILL)  # (stopped or not)
        proc.communicate(timeout=60)


def _resume(run: Path) -> str:
    out = subprocess.run(_rig('resume', str(run)), capture_output=True, text=True,
                         timeout=TIMEOUT_S)
    assert out.returncode == 0, out.stdout + out.stderr
    return out.stdout


@pytest.fixture(scope='module')
def expected_rewards() -> list[list[float]]:
    """The uninterrupted run: the same oracle episodes in process."""
    played = play_episodes(GrowSpaceEnv('control', 'easy'), OracleAgent(),
                           range(SEED, SEED + EPISODES))
    return [list(row) for row in played.rewards]


def _check_every_step_once(run: Path, expected: list[list[float]]) -> None:
    state = read_journal(run / 'journal.jsonl')
    assert state.duplicated == 0 and state.pending is None
    assert [e.index for e in state.episodes] == list(range(EPISODES))
    for episode, rewards in zip(state.episodes, expected):
        assert [s.step for s in episode.steps] == list(range(1, 51))
        got = np.array([s.reward for s in episode.steps])
        assert got.tobytes() == np.array(rewards).tobytes()  # bit for bit
    recording = run / 'recording'
    with Bag(recording) as bag:
        episodes = read_episodes(bag)
    for index in range(EPISODES):
        ours = [e for e in episodes if e.reset_id == reset_id_of(index)]
        assert len(ours) == 1, f'episode {index} recorded {len(ours)} times'
        assert [int(s.result.step) for s in ours[0].stepped] == list(range(1, 51))
        assert not ours[0].damaged
    assert resimulate(recording).ok


@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
@pytest.mark.parametrize('damage', ['none', 'step_not_journaled', 'recording_tail_lost'])
def test_sigkill_mid_episode_then_resume_runs_every_step_exactly_once(tmp_path, damage,
                                                                     expected_rewards):
    run = tmp_path / 'run'
    _start_and_kill(run)
    journal = run / 'journal.jsonl'
    lines = journal.read_text().splitlines(keepends=True)
    if damage == 'step_not_journaled':
        # The runner died between the chamber's answer and its journal line: the recording
        # holds the step, the journal only its intent. Resume must adopt it, not send it again.
        from growspace_sim.recording import wait_until_free
        assert wait_until_free(run / 'recording', 60)
        episode = read_journal(journal).episodes[-1]
        last = recorded_episodes(run / 'recording')[episode.reset_id][-1].step
        intent = next(i for i, line in enumerate(lines) if '"event":"intent"' in line
                      and f'"step":{last},' in line and f'"episode":{episode.index},' in line)
        journal.write_text(''.join(lines[:intent + 1]))
    elif damage == 'recording_tail_lost':
        # The chamber died before its last file reached the disk: the journal holds steps the
        # recording lacks. Resume must re-simulate them into the recording, once.
        from growspace_sim.recording import wait_until_free
        assert wait_until_free(run / 'recording', 60)
        split_files(run / 'recording')[-1].unlink()
        journaled = read_journal(journal).episodes[-1]
        recorded = recorded_episodes(run / 'recording').get(journaled.reset_id)
        lost = len(journaled.steps) - (recorded[-1].step if recorded else 0)
    out = _resume(run)
    assert 'resumed episode 1' in out
    events = [json.loads(line) for line in journal.read_text().splitlines()]
    resumed = [e for e in events if e['event'] == 'resume']
    assert len(resumed) == 1
    if damage == 'step_not_journaled':
        assert resumed[0]['adopted'], resumed
    if damage == 'recording_tail_lost':
        assert resumed[0]['caught_up'] == lost
    assert 'finished: 2 episode(s)' in out
    _check_every_step_once(run, expected_rewards)


def test_soak_script_injects_faults_and_loses_nothing(tmp_path):
    """scripts/soak_rig.py, short: 100 steps, 4 faults, each followed by a resume."""
    out = subprocess.run([sys.executable, str(Path(__file__).resolve().parents[2] / 'scripts'
                                              / 'soak_rig.py'), '--chamber', 'sim',
                          '--steps', '100', '--faults',
                          '4', '--seed', '5', '--out', str(tmp_path / 'soak')],
                         capture_output=True, text=True, timeout=2 * TIMEOUT_S)
    assert out.returncode == 0, out.stdout + out.stderr
    last = out.stdout.strip().splitlines()[-1]
    assert last.startswith('soak: steps=100 faults=4 resumes=4 lost=0 duplicated=0 '
                           'unreadable_files=0 max_resume_s='), last


def test_attached_to_a_running_sim_node_the_runner_steps_it_and_its_recording_holds_it(
        tmp_path, expected_rewards):
    """--chamber attach: the same loop on a lockstep chamber someone else started."""
    from ros_helpers import NodeProcess

    node = NodeProcess('-p', f'seed:={SEED}', '-p', f'record_path:={tmp_path / "node.mcap"}',
                       namespace='/rig_attach')
    try:
        out = subprocess.run(_rig('run', str(tmp_path / 'run'), '--chamber', 'attach',
                                  '--namespace', '/rig_attach', '--episodes', '1', '--seed',
                                  str(SEED), '--step-timeout', '60'),
                             capture_output=True, text=True, timeout=TIMEOUT_S)
    finally:
        code, log = node.stop()
    assert out.returncode == 0, out.stdout + out.stderr
    assert 'episode 1/1 step 50/50 | 50/50 steps done | finished' in out.stdout
    episode = read_journal(tmp_path / 'run' / 'journal.jsonl').episodes[0]
    rewards = np.array([s.reward for s in episode.steps])
    assert rewards.tobytes() == np.array(expected_rewards[0]).tobytes()
    with Bag(tmp_path / 'node.mcap') as bag:
        ours = [e for e in read_episodes(bag) if e.reset_id == reset_id_of(0)]
    assert [int(s.result.step) for s in ours[0].stepped] == list(range(1, 51))
