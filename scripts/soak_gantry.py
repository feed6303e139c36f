"""The rig soak (``soak_rig.py --chamber rig``): ``growspace-rig`` attached to ``gantry_node``
(lockstep, growth period, photo light) on the GRBL emulator (a pseudo-terminal, homing enabled:
``$22=1``) and ``camera_node`` (the photo twin), with faults injected at random:

- ``unplug``: the emulator's pty closed, then a fresh controller on the same path after a
  moment (its power went with the cable): GRBL powers up in Alarm, position lost;
- ``camera_kill``: SIGKILL to camera_node, started again after a moment;
- ``gantry_kill``: SIGKILL to gantry_node, started again with ``resume_path`` on its recording;
  the runner's step is never answered: it times out (``--step-timeout``) and is resumed;
- ``runner_kill``: SIGKILL to the runner, then ``growspace-rig resume``;
- ``disk_full``: the run directory's file system (a small tmpfs in the soak's own mount
  namespace) filled to ENOSPC: the runner's next journal line fails, it stops; the ballast is
  removed (a person frees space) and the run resumed. The gantry's recording lives on another
  file system here: a gantry recorder that meets a full disk stops recording (the machine goes
  on), which this soak does not inject;
- ``power_cut``: SIGKILL to the runner, gantry_node and camera_node at once (one process group),
  the controller restarted (power-up in Alarm), a journal line half written; then all started
  again, gantry_node with ``resume_path``, and the run resumed.

Where the gantry is in alarm, its steps are refused and the runner prints WAITING FOR A PERSON;
the soak, playing the person, calls ``gantry/home`` then (never ``gantry/unlock``). The photo
twin is not stateless: a restarted camera_node grows its plant again from the episode's start
under the light of the step asked (its history is gone), a plant the pipeline may refuse to read
(e.g. ``plants: 2 stem base(s)``); after 15 refusals of one step in a row the person restarts
camera_node with another twin_seed (other photo conditions), counted as re-mounted. A camera
gone or an unplug fails the step in progress: the runner retries it (same action, a new
step_id) and the gantry, which counts only answered steps, does it once. ``resumes`` counts the
``growspace-rig resume`` runs; unplug and camera_kill are recovered without one (the runner
waits and retries).

The photoperiod: a one-minute night (``lights_off``/``lights_on``, whole minutes of wall time)
a few minutes into the soak; steps begun before it wait, lamp off, for the morning.
"""

from __future__ import annotations

import datetime as dt
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import threading
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'tests'))

from grbl_emulator import GrblEmulator  # noqa: E402

FAULTS = ('unplug', 'camera_kill', 'gantry_kill', 'runner_kill', 'disk_full', 'power_cut')
RIG = {10: 1, 20: 1, 22: 1, 30: 1000, 32: 1, 110: 6000, 111: 6000, 112: 6000, 130: 900,
       131: 900, 132: 500}  # tests/gantry/test_gantry_node.py's rig, with homing enabled
NAMESPACE = '/soak_rig'
TMPFS_BYTES = 8 * 1024 * 1024
REMOUNT_AFTER = 15  # camera refusals of one step in a row before the person steps in


def _executable(package: str, name: str) -> str:
    from ament_index_python.packages import get_package_prefix

    return os.path.join(get_package_prefix(package), 'lib', package, name)


class Rig:
    """The emulator, camera_node and gantry_node, and the person who homes the gantry."""

    def __init__(self, out: Path, growth_s: float, night: tuple[str, str]) -> None:
        self.out = out
        self.recording = out / 'gantry'
        self.grbl = GrblEmulator(RIG, speedup=100.0, link_dir=out).start()
        self.growth_s = growth_s
        self.night = night
        self.camera: subprocess.Popen | None = None
        self.gantry: subprocess.Popen | None = None
        self.homed = 0
        self.twin_seed = 2
        self.remounted = 0  # camera_node restarted by the person after repeated refusals
        self._log = open(out / 'nodes.log', 'a')  # noqa: SIM115 - closed in close()

    def start_camera(self) -> None:
        self.camera = subprocess.Popen(
            [_executable('growspace_camera', 'camera_node'), '--ros-args', '-r',
             f'__ns:={NAMESPACE}', '-p', 'source:=twin', '-p', f'twin_seed:={self.twin_seed}'],
            stdout=self._log, stderr=subprocess.STDOUT)

    def start_gantry(self) -> None:
        resume = ['-p', f'resume_path:={self.recording}'] if self.recording.is_dir() else []
        lights_off, lights_on = self.night
        self.gantry = subprocess.Popen(
            [_executable('growspace_gantry', 'gantry_node'), '--ros-args', '-r',
             f'__ns:={NAMESPACE}', '-p', f'port:={self.grbl.port}', '-p', 'seed:=3',
             '-p', f'record_path:={self.recording}', '-p', 'record_max_bytes:=2000000',
             '-p', 'camera:=camera/capture', '-p', 'photo_light:=true',
             '-p', 'photo_settle_s:=0.05', '-p', 'capture_timeout_s:=20.0',
             '-p', f'growth_s:={self.growth_s}', '-p', f'lights_on:={lights_on}',
             '-p', f'lights_off:={lights_off}', '-p', 'watchdog_s:=0.0', *resume],
            stdout=self._log, stderr=subprocess.STDOUT)

    def home(self) -> bool:
        """A person's gantry/home (the controller in alarm after a power-up)."""
        from growspace_sim.node.rclpy_transport import RclpyTransport
        from growspace_sim.ros import types

        transport = RclpyTransport(f'soak_person_{os.getpid()}', NAMESPACE)
        try:
            client = transport.client('std_srvs/srv/Trigger', 'gantry/home')
            answer: list = []
            deadline = time.monotonic() + 30.0
            while not client.ready() and time.monotonic() < deadline:
                transport.spin_once(0.05)
            client.call(types.new('std_srvs/srv/Trigger_Request'), answer.append)
            while not answer and time.monotonic() < deadline:
                transport.spin_once(0.05)
            self.homed += bool(answer and answer[0].success)
            return bool(answer and answer[0].success)
        finally:
            transport.close()

    def kill(self, which: str) -> None:
        proc = getattr(self, which)
        if proc is not None and proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            proc.wait()

    def close(self) -> None:
        for proc in (self.gantry, self.camera):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    proc.kill()
        self.grbl.stop()
        self._log.close()


class Runner:
    """One ``growspace-rig`` process, its output read line by line (the person reads it)."""

    def __init__(self, command: list[str], log: Path, on_waiting) -> None:
        self.proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True)
        self.waiting = threading.Event()
        self._thread = threading.Thread(target=self._read, args=(log, on_waiting), daemon=True)
        self._thread.start()

    def _read(self, log: Path, on_waiting) -> None:
        with open(log, 'a') as stream:
            for line in self.proc.stdout:
                stream.write(line)
                stream.flush()
                if 'WAITING FOR A PERSON' in line:
                    on_waiting(line)

    def wait(self, timeout: float) -> int:
        code = self.proc.wait(timeout=timeout)
        self._thread.join(10)
        return code


def _mount_tmpfs(path: Path) -> None:
    path.mkdir(parents=True)
    subprocess.run(['mount', '-t', 'tmpfs', '-o', f'size={TMPFS_BYTES}', 'tmpfs', str(path)],
                   check=True)


def _fill(path: Path) -> Path:
    """Fill the file system of ``path`` to ENOSPC; returns the ballast file."""
    ballast = path / 'ballast'
    with open(ballast, 'wb', buffering=0) as stream:
        for size in (65536, 4096, 256, 16, 1):  # to the last byte the file system gives
            try:
                while stream.write(b'\0' * size):
                    pass
            except OSError:
                pass
    return ballast


def run(args, count) -> int:
    """The rig soak (``args`` of soak_rig.py); ``count`` reads the run back (soak_rig.count)."""
    if os.environ.get('SOAK_RIG_MOUNT_NS') != '1':  # a mount namespace of our own: the tmpfs
        os.environ['SOAK_RIG_MOUNT_NS'] = '1'
        os.execvp('unshare', ['unshare', '-m', sys.executable, *sys.argv])
    from growspace_sim.core.photoperiod import Photoperiod
    from growspace_sim.replay import Bag, read_episodes
    from growspace_sim.ros import loopback

    loopback.confine()
    out: Path = args.out
    out.mkdir(parents=True)
    run_dir = out / 'fs' / 'run'
    _mount_tmpfs(out / 'fs')
    episodes = -(-args.steps // 50)
    total = episodes * 50
    rng = random.Random(args.seed)
    points = sorted(rng.sample(range(3, total - 2), args.faults)) if args.faults else []
    start = dt.datetime.now(dt.UTC) + dt.timedelta(minutes=args.night_after_min)
    night = (f'{start:%H:%M}', f'{start + dt.timedelta(minutes=1):%H:%M}')
    rig = Rig(out, args.growth_s, night)
    log = out / 'runner.log'

    calls = threading.Lock()
    refused: list[str] = []  # the camera's refusals of the same step, in a row

    def person(line: str) -> None:
        with calls:
            if rig.grbl.state == 'Alarm':
                rig.home()
            step = line.split(' was refused')[0]
            if 'error: camera:' not in line or (refused and refused[-1] != step):
                refused.clear()
            if 'error: camera:' in line:
                refused.append(step)
            if len(refused) >= REMOUNT_AFTER:  # the twin regrew a plant it cannot read:
                refused.clear()  # a person re-mounts the camera (other photo conditions)
                rig.kill('camera')
                rig.twin_seed += 1
                rig.remounted += 1
                rig.start_camera()

    def steps() -> int:
        try:
            return (run_dir / 'journal.jsonl').read_bytes().count(b'"event":"step"')
        except FileNotFoundError:
            return 0

    faults = resumes = 0
    resume_times: list[float] = []
    kinds: dict[str, int] = {}
    measuring: list[tuple[float, int]] = []  # (when a resume began, steps then)
    command = [sys.executable, '-m', 'growspace_sim.rig.cli', 'run', str(run_dir), '--chamber',
               'attach', '--namespace', NAMESPACE, '--episodes', str(episodes), '--seed',
               str(args.seed), '--step-timeout', str(args.step_timeout), '--retry-period', '1']

    def resume() -> Runner:
        nonlocal resumes
        resumes += 1
        measuring.append((time.monotonic(), steps()))
        return Runner([*command[:3], 'resume', str(run_dir)], log, person)

    def measure() -> None:
        if measuring and steps() > measuring[-1][1]:
            resume_times.append(time.monotonic() - measuring.pop()[0])

    try:
        rig.start_camera()
        rig.start_gantry()
        deadline = time.monotonic() + 120
        while rig.grbl.state != 'Alarm' or not rig.home():  # the person homes it at first
            if time.monotonic() > deadline:
                raise TimeoutError('the gantry could not be homed at start')
            time.sleep(0.5)
        runner = Runner(command, log, person)
        while True:
            point = max(points[0], steps() + 1) if points else None
            if point is not None and point >= total:
                point = None  # the run ends first
            while runner.proc.poll() is None and (point is None or steps() < point):
                measure()
                time.sleep(0.05)  # polling a file another process writes
            measure()
            if runner.proc.poll() is not None:
                code = runner.wait(60)
                if code == 0:
                    break
                measuring.clear()  # that resume never got to a step
                runner = resume()  # it stopped on its own: a step timed out, a full disk
                continue
            points.pop(0)
            fault = rng.choice(FAULTS)
            kinds[fault] = kinds.get(fault, 0) + 1
            faults += 1
            print(f'fault {faults}: {fault} at step {steps()}', flush=True)
            if fault == 'unplug':  # the runner waits for the person, then retries
                rig.grbl.unplug()
                time.sleep(rng.uniform(0.5, 3.0))  # the cable out for a moment
                rig.grbl.replug()
            elif fault == 'camera_kill':  # the step in progress fails, the runner retries
                rig.kill('camera')
                time.sleep(rng.uniform(0.5, 3.0))
                rig.start_camera()
            elif fault == 'gantry_kill':  # the runner's step times out: it stops, resumed
                rig.kill('gantry')
                rig.start_gantry()
            elif fault == 'runner_kill':
                runner.proc.send_signal(signal.SIGKILL)
                runner.wait(60)
                runner = resume()
            elif fault == 'disk_full':  # its next journal line fails: it stops, resumed
                ballast = _fill(run_dir.parent)
                runner.wait(args.step_timeout * 4)
                ballast.unlink()
            else:  # power_cut
                runner.proc.send_signal(signal.SIGKILL)
                rig.kill('gantry')
                rig.kill('camera')
                runner.wait(60)
                rig.grbl.restart()
                with open(run_dir / 'journal.jsonl', 'ab') as stream:
                    stream.write(b'{"event":"step","episode":')
                rig.start_camera()
                rig.start_gantry()
                runner = resume()
        rig.close()
        # The tmpfs goes with this process's mount namespace: keep the run directory first.
        subprocess.run(['cp', '-a', str(run_dir), str(out / 'run')], check=False)
        totals = count(run_dir, episodes, rig.recording)
        period = Photoperiod(night[1], night[0])
        with Bag(rig.recording) as bag:
            short = sum(1 for e in read_episodes(bag) for s in e.stepped
                        if s.commands and period.lit_seconds(
                            s.commands[-1].header.stamp.sec
                            + s.commands[-1].header.stamp.nanosec / 1e9,
                            s.log_time / 1e9) < args.growth_s * 0.999)
    finally:
        if not rig._log.closed:
            rig.close()
    print(f'faults by kind: {kinds}; homed by the person: {rig.homed}; camera re-mounted by '
          f'the person: {rig.remounted}; steps shorter than '
          f'their growth period: {short}; night {night[0]}-{night[1]} UTC', flush=True)
    print(f'soak: steps={totals["steps"]} faults={faults} resumes={resumes} '
          f'lost={totals["lost"]} duplicated={totals["duplicated"]} '
          f'unreadable_files={totals["unreadable_files"]} '
          f'max_resume_s={max(resume_times, default=0.0):.1f}')
    bad = totals['lost'] or totals['duplicated'] or totals['unreadable_files'] or short
    return 1 if bad else 0
