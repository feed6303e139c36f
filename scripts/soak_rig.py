"""Soak the experiment runner: a long run with faults injected at random, each followed by
``growspace-rig resume``; at the end, count what was lost, duplicated or unreadable.

    python scripts/soak_rig.py --steps 1000 --faults 20 --seed 1 --out /tmp/soak
    python scripts/soak_rig.py --chamber sim --steps 1000 --faults 20 --seed 1 --out /tmp/s2

``--chamber rig`` (the default; root: a tmpfs in its own mount namespace for the full disk):
gantry_node on the GRBL emulator with the photo twin, its faults and checks in
``soak_gantry.py``. ``--chamber sim``: sim_node, the faults below.

Faults, each at a random step of the run, before the step is sent or after its answer (the
runner stops itself there, ``rig.faults``: a fault never races a fast run to its end):
- ``runner_kill``: SIGKILL to the runner (its sim_node stops by itself and finishes its file);
- ``runner_term``: SIGTERM to the runner (it stops cleanly);
- ``node_kill``: SIGKILL to the runner's sim_node (the runner sees it die and exits 1);
- ``power_cut``: SIGKILL to the whole process group (runner and node at once), then what a
  power cut can do beyond that: the recording's last file cut short where its last pages were
  not yet on disk, and a journal line half written.

The run's episodes are as many as ``--steps`` needs (50 steps each). Ends with one line:
``soak: steps=.. faults=.. resumes=.. lost=.. duplicated=.. unreadable_files=.. max_resume_s=..``
where ``steps`` counts the steps in both the journal and the recording, ``lost`` the steps of
the run missing from either, ``duplicated`` those in either more than once, ``unreadable_files``
the recording's files that do not open, and ``max_resume_s`` the longest time from starting
``resume`` to its first new journaled step. Exit 0 when lost, duplicated and unreadable are 0.

This soak exercises the runner, the journal, the split recording and sim_node's resume.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import tempfile
import time

from growspace_sim.rig.faults import PAUSE_ENV

FAULTS = ('runner_kill', 'runner_term', 'node_kill', 'power_cut')
EPISODE_LENGTH = 50


def _rig(*args: str) -> list[str]:
    return [sys.executable, '-m', 'growspace_sim.rig.cli', *args]


def _steps(run: Path) -> int:
    """Steps the run's journal holds (a torn last line is none)."""
    from growspace_sim.rig.rundir import read_journal

    return read_journal(run / 'journal.jsonl').steps_done


def _children(pid: int) -> list[int]:
    """Every descendant of ``pid`` (from /proc), deepest last."""
    out, todo = [], [pid]
    while todo:
        parent = todo.pop()
        for task in Path(f'/proc/{parent}/task').glob('*'):
            try:
                kids = (task / 'children').read_text().split()
            except OSError:
                continue
            for kid in map(int, kids):
                out.append(kid)
                todo.append(kid)
    return out


def _node_pid(runner: int) -> int | None:
    for pid in _children(runner):
        try:
            cmdline = Path(f'/proc/{pid}/cmdline').read_bytes()
        except OSError:
            continue
        if b'growspace_sim.node.main' in cmdline or b'sim_node' in cmdline:
            return pid
    kids = _children(runner)
    return kids[-1] if kids else None


def _cut_last_file(run: Path, rng: random.Random) -> None:
    from growspace_sim.recording import split_files, wait_until_free

    wait_until_free(run / 'recording', 60)
    files = split_files(run / 'recording') if (run / 'recording').is_dir() else []
    if files:
        data = files[-1].read_bytes()
        files[-1].write_bytes(data[:int(len(data) * rng.uniform(0.3, 0.95))])


def _tear_journal(run: Path) -> None:
    with open(run / 'journal.jsonl', 'ab') as stream:
        stream.write(b'{"event":"step","episode":')


def _wait_for_steps(proc: subprocess.Popen, run: Path, target: int, timeout_s: float) -> None:
    """Until the journal holds ``target`` steps (a resume's first new one: it is timed)."""
    deadline = time.monotonic() + timeout_s
    while _steps(run) < target:
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f'soak: the resumed runner journaled no new step '
                               f'(exit {proc.poll()}; {timeout_s:g} s)')
        time.sleep(0.02)  # polling a file another process writes


def _paused(proc: subprocess.Popen, timeout_s: float) -> bool:
    """Until the runner stopped itself at its pause point (True) or ended (False)."""
    deadline = time.monotonic() + timeout_s
    while True:
        info = os.waitid(os.P_PID, proc.pid,
                         os.WSTOPPED | os.WEXITED | os.WNOWAIT | os.WNOHANG)
        if info is not None:
            return info.si_code == os.CLD_STOPPED
        if time.monotonic() > deadline:
            raise RuntimeError(f'soak: the runner neither reached its fault nor ended in '
                               f'{timeout_s:g} s')
        time.sleep(0.02)  # (waitid cannot wait with a deadline)


def count(run: Path, episodes: int, recording: Path | None = None) -> dict[str, int]:
    """Steps once, lost, duplicated (journal and recording), unreadable recording files.

    ``recording``: the chamber's split recording (default: the run directory's). A step of the
    recording counts only with its camera image (a rig step without its photo is lost)."""
    from growspace_sim.recording import repair, split_files
    from growspace_sim.replay import Bag, read_episodes, ReplayError
    from growspace_sim.rig.rundir import read_journal
    from growspace_sim.rig.runner import reset_id_of

    state = read_journal(run / 'journal.jsonl')
    journal = {(e.index, s.step) for e in state.episodes for s in e.steps}
    duplicated = state.duplicated
    recording = recording or run / 'recording'
    repair(recording)
    unreadable = 0
    for path in split_files(recording):
        try:
            Bag(path).close()
        except ReplayError:
            unreadable += 1
    recorded: dict[tuple[int, int], int] = {}
    with Bag(recording) as bag:
        for episode in read_episodes(bag):
            index = episode.reset_id - reset_id_of(0)
            if not 0 <= index < episodes:
                continue  # the node's own start-up episodes
            for record in episode.stepped:
                if 'camera/image_raw' not in record.outputs:
                    continue
                key = (index, int(record.result.step))
                recorded[key] = recorded.get(key, 0) + 1
    duplicated += sum(n - 1 for n in recorded.values() if n > 1)
    wanted = {(e, s) for e in range(episodes) for s in range(1, EPISODE_LENGTH + 1)}
    both = wanted & journal & set(recorded)
    return {'steps': len(both), 'lost': len(wanted - both), 'duplicated': duplicated,
            'unreadable_files': unreadable}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--steps', type=int, default=1000, help='steps of the run (>= 50)')
    parser.add_argument('--faults', type=int, default=20, help='faults to inject (>= 0)')
    parser.add_argument('--seed', type=int, default=1, help='seed of the faults and the run')
    parser.add_argument('--out', type=Path, required=True, help='a new directory for the run')
    parser.add_argument('--step-timeout', type=float, default=None, metavar='SECONDS',
                        help='default 600 (sim), 90 (rig: a step may wait out a night)')
    parser.add_argument('--chamber', choices=('rig', 'sim'), default='rig')
    parser.add_argument('--growth-s', type=float, default=0.1,
                        help='rig: growth_s of each step [s]')
    parser.add_argument('--night-after-min', type=int, default=3,
                        help='rig: a one-minute night begins this many minutes in')
    args = parser.parse_args(argv)
    if args.step_timeout is None:
        args.step_timeout = 90.0 if args.chamber == 'rig' else 600.0
    if args.steps < EPISODE_LENGTH:
        parser.error(f'argument --steps: {args.steps} is too few; at least {EPISODE_LENGTH}.')
    if args.faults < 0:
        parser.error(f'argument --faults: {args.faults} is not allowed; >= 0.')
    if args.out.exists():
        parser.error(f'argument --out: {args.out} exists already; give a new directory.')
    if args.chamber == 'rig':
        import soak_gantry

        return soak_gantry.run(args, count)
    episodes = -(-args.steps // EPISODE_LENGTH)
    total = episodes * EPISODE_LENGTH
    if args.faults > (total - 3) // 3:
        parser.error(f'argument --faults: {args.faults} is too many for {total} steps; at most '
                     f'{(total - 3) // 3} (a resume runs 2 steps before the next fault).')
    rng = random.Random(args.seed)
    # At least 2 steps apart: a resume's first new step is timed before its fault.
    points = [point + 2 * i for i, point in enumerate(sorted(
        rng.sample(range(3, total - 2 * args.faults), args.faults)))]
    run = args.out
    command = _rig('run', str(run), '--episodes', str(episodes), '--seed', str(args.seed),
                   '--record-max-bytes', '1000000', '--step-timeout', str(args.step_timeout))
    faults = resumes = 0
    resume_times: list[float] = []
    stages = random.Random(args.seed + 1)  # its own stream: the faults' kinds stay those of seed
    log = open(os.devnull, 'w')  # noqa: SIM115 - the runner's lines are not the soak's
    quiet = {k: v for k, v in os.environ.items() if k != PAUSE_ENV}
    while True:
        started = time.monotonic()
        before = _steps(run)
        # The runner stops itself at the next fault's point (PAUSE_ENV), after a resume's first
        # new step (points are 2 apart; the guard is for a resume that adopted more).
        point = max(points[0], before + 1 + bool(resumes)) if points else None
        stage = stages.choice(('intent', 'step'))  # before the step is sent, or after its answer
        env = {**quiet, PAUSE_ENV: f'{stage}:{point}'} if point else quiet
        errors = tempfile.TemporaryFile()  # noqa: SIM115 - read when the runner failed
        proc = subprocess.Popen(command, stdout=log, stderr=errors, env=env,
                                start_new_session=True)  # its own group: the "power" line
        try:
            if resumes:
                _wait_for_steps(proc, run, before + 1, args.step_timeout)
                resume_times.append(time.monotonic() - started)
            if not _paused(proc, args.step_timeout * max(1, (point or total) - before)):
                proc.wait(timeout=args.step_timeout)
                if proc.returncode != 0 or point is not None:
                    errors.seek(0)
                    said = errors.read().decode(errors='replace')
                    print(f'soak: the runner ended (exit {proc.returncode}) before its fault '
                          f'at {stage} of step {point}:\n{said}' if point else
                          f'soak: the runner failed (exit {proc.returncode}):\n{said}',
                          file=sys.stderr)
                    return 1
                break
            points.pop(0)
            fault = rng.choice(FAULTS)
            if fault == 'power_cut':
                os.killpg(proc.pid, signal.SIGKILL)
            elif fault == 'node_kill':
                node = _node_pid(proc.pid)
                if node is None:
                    print('soak: the runner has no sim_node to kill', file=sys.stderr)
                    return 1
                os.kill(node, signal.SIGKILL)
            else:
                proc.send_signal(signal.SIGKILL if fault == 'runner_kill' else signal.SIGTERM)
            if fault in ('runner_term', 'node_kill'):
                proc.send_signal(signal.SIGCONT)  # a stopped runner acts once it runs again
            proc.wait(timeout=args.step_timeout)
        finally:
            if proc.poll() is None:  # a failure above: never leave a runner stopped, or its node
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
            errors.close()
        if fault == 'power_cut':
            _cut_last_file(run, rng)
            _tear_journal(run)
        faults += 1
        resumes += 1
        where = 'before step' if stage == 'intent' else 'after step'
        print(f'fault {faults}: {fault} {where} {point}', flush=True)
        command = _rig('resume', str(run))
    totals = count(run, episodes)
    print(f'soak: steps={totals["steps"]} faults={faults} resumes={resumes} '
          f'lost={totals["lost"]} duplicated={totals["duplicated"]} '
          f'unreadable_files={totals["unreadable_files"]} '
          f'max_resume_s={max(resume_times, default=0.0):.1f}')
    return 0 if not (totals['lost'] or totals['duplicated'] or totals['unreadable_files']) \
        else 1


if __name__ == '__main__':
    sys.exit(main())
