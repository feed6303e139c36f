"""A ``growspace-rig`` run attached to ``gantry_node`` + ``camera_node`` (the GRBL emulator on a
pseudo-terminal, the photo twin) survives a SIGKILL of gantry_node mid-episode: restarted with
``resume_path`` on its own split recording, it keeps the episode's reset_id and step count, and
``growspace-rig resume`` finishes the episode. Read back, the recording holds every step exactly
once, each with its photo; the journal too.
"""

from __future__ import annotations

from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest

from growspace_sim.recording import split_files
from growspace_sim.replay import Bag, read_episodes
from growspace_sim.rig.rundir import read_journal
from growspace_sim.rig.runner import reset_id_of
from test_rig_ros import grbl, NAMESPACE, start_camera, start_gantry  # noqa: F401
from ros_helpers import wait_until_idle
from waiting import wait_until

pytestmark = pytest.mark.slow

EPISODE_LENGTH = 50
TIMEOUT_S = 600.0


def _rig(*args: str) -> list[str]:
    return [sys.executable, '-m', 'growspace_sim.rig.cli', *args]


def _journaled(run: Path) -> int:
    try:
        return (run / 'journal.jsonl').read_bytes().count(b'"event":"step"')
    except FileNotFoundError:
        return 0


def _gantry(grbl, recording: Path, *args: str):  # noqa: F811 - the fixture's value
    return start_gantry(grbl, recording, '-p', 'capture_timeout_s:=30.0', '-p',
                        'growth_s:=0.05', '-p', 'record_max_bytes:=400000', '-p',
                        'watchdog_s:=0.0', *args)


@pytest.mark.usefixtures('own_domain')  # it kills or stops a node
def test_a_killed_gantry_node_resumes_the_episode_and_every_step_is_recorded_once_with_its_photo(
        grbl, tmp_path):  # noqa: F811
    recording, run = tmp_path / 'gantry', tmp_path / 'run'
    camera = start_camera()
    gantry = _gantry(grbl, recording)
    runner = None
    try:
        wait_until_idle(NAMESPACE)
        runner = subprocess.Popen(
            _rig('run', str(run), '--chamber', 'attach', '--namespace', NAMESPACE,
                 '--episodes', '1', '--seed', '5', '--step-timeout', '15', '--retry-period',
                 '1'), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        # (polled often: the kill must land mid-episode, soon after the seventh step)
        wait_until(lambda: _journaled(run) >= 7 or runner.poll() is not None, TIMEOUT_S,
                   'the runner journals seven steps', between=lambda: time.sleep(0.02))
        assert _journaled(run) >= 7, runner.communicate()[0]
        gantry.stop(signal.SIGKILL)  # mid-episode: in a move, a growth period or a photo
        killed_at = _journaled(run)
        out = runner.communicate(timeout=TIMEOUT_S)[0]  # the step it waits for times out
        assert runner.returncode == 1, out
        assert killed_at < EPISODE_LENGTH

        gantry = _gantry(grbl, recording, '-p', f'resume_path:={recording}')
        wait_until_idle(NAMESPACE)
        resumed = subprocess.run(_rig('resume', str(run)), capture_output=True, text=True,
                                 timeout=TIMEOUT_S)
    finally:
        if runner is not None and runner.poll() is None:
            runner.kill()
        gantry_code, gantry_log = gantry.stop(signal.SIGTERM)
        camera.stop(signal.SIGTERM)
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr + gantry_log
    assert 'finished' in resumed.stdout, resumed.stdout
    assert 'resumed episode reset_id' in gantry_log, gantry_log
    assert gantry_code == 0, gantry_log

    state = read_journal(run / 'journal.jsonl')
    assert state.duplicated == 0
    assert [s.step for s in state.episodes[0].steps] == list(range(1, EPISODE_LENGTH + 1))
    assert len(split_files(recording)) >= 2  # split by size (record_max_bytes)
    with Bag(recording) as bag:
        assert not bag.damage
        ours = [e for e in read_episodes(bag) if e.reset_id == reset_id_of(0)]
    assert len(ours) == 1, [(e.reset_id, e.n_steps) for e in ours]
    steps = ours[0].stepped
    assert [int(s.result.step) for s in steps] == list(range(1, EPISODE_LENGTH + 1))
    assert all(not s.result.info for s in steps)
    assert all('camera/image_raw' in s.outputs for s in steps)  # each with its photo
