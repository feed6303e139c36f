"""The gantry driver's own CPU cost per command, against the pty GRBL emulator of the tests.

Method (fixed): gantry_node's logic (``GantryNode`` over the in-process transport, CDR included)
runs in the main thread and the emulator in its own thread; ``time.thread_time()`` of the main
thread counts the driver alone. After a reset (which establishes the machine position),
a lockstep episode of random discrete actions (control, 50 steps) with moves sped up
``--speedup`` times; per command = all driver CPU of the episode
(command handling, streaming, status parsing, polls while the machine moves, the answer) over
the commands. Idle = the driver's CPU per second while nothing is commanded (polls at 100 Hz,
status requests at 10 Hz). Best of ``--repeats``.

    PYTHONPATH=tests python scripts/bench_gantry.py      # inside the sourced workspace
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'tests'))

from grbl_emulator import GrblEmulator  # noqa: E402
from growspace_gantry import calibration  # noqa: E402
from growspace_gantry.controller import GrblController, Log  # noqa: E402
from growspace_gantry.link import SerialLink  # noqa: E402
from growspace_gantry.main import default_calibration  # noqa: E402
from growspace_gantry.node import GantryNode  # noqa: E402
from growspace_gantry.settings import GantryParams  # noqa: E402
from growspace_sim.core.config import SimConfig  # noqa: E402
from growspace_sim.node.fake import FakeTransport  # noqa: E402
from growspace_sim.ros import convert  # noqa: E402
from growspace_sim.ros import types  # noqa: E402

RIG = {10: 1, 20: 1, 22: 0, 30: 1000, 32: 1, 110: 6000, 111: 6000, 112: 6000, 130: 900,
       131: 900, 132: 500}
STEPS = 50


def episode(speedup: float, seed: int) -> tuple[float, float, float]:
    """(driver CPU per command [s], wall per command [s], driver CPU per idle second [s])."""
    with tempfile.TemporaryDirectory() as tmp, GrblEmulator(RIG, speedup=speedup,
                                                            link_dir=tmp) as grbl:
        t = FakeTransport('growspace_gantry')
        cal = calibration.load(default_calibration())
        controller = GrblController(lambda: SerialLink(grbl.port), cal,
                                    Log(t.logger.warn, t.logger.info), 0.1)
        node = GantryNode(t, controller, SimConfig(), GantryParams(port=grbl.port, seed=seed,
                                                                   watchdog_s=0.0))

        def until(done) -> None:
            deadline = time.monotonic() + 30.0
            while not done():
                assert time.monotonic() < deadline, t.warnings
                node.poll()
                time.sleep(0.01)  # the node's 100 Hz poll timer
        until(lambda: controller.ready)
        t.inject('reset', types.new(types.RESET_REQUEST, reset_id=1, has_seed=True, seed=seed))
        until(lambda: len(t.messages('step_result')) == 1)
        assert t.messages('step_result')[-1].info == '', t.messages('step_result')[-1]
        rng = np.random.default_rng(seed)
        cpu, wall = time.thread_time(), time.perf_counter()
        for step_id in range(1, STEPS + 1):
            n = len(t.messages('step_result'))
            t.inject('light/command', types.new(types.LIGHT_COMMAND, step_id=step_id,
                                                mode=convert.MODE_DISCRETE,
                                                action=int(rng.integers(5))))
            until(lambda n=n: len(t.messages('step_result')) > n)
            assert t.messages('step_result')[-1].info == '', t.messages('step_result')[-1]
        per_cmd = (time.thread_time() - cpu) / STEPS
        per_wall = (time.perf_counter() - wall) / STEPS
        cpu, end = time.thread_time(), time.monotonic() + 2.0
        while time.monotonic() < end:
            node.poll()
            time.sleep(0.01)
        idle = (time.thread_time() - cpu) / 2.0
        node.close()
        return per_cmd, per_wall, idle


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--speedup', type=float, default=50.0)
    args = parser.parse_args()
    runs = [episode(args.speedup, seed) for seed in range(args.repeats)]
    best = min(runs)
    print(f'driver CPU per command: {best[0] * 1e3:.3f} ms (best of {args.repeats}; all: '
          f'{", ".join(f"{r[0] * 1e3:.3f}" for r in runs)} ms); wall per command with moves '
          f'{args.speedup:g}x faster: {best[1] * 1e3:.1f} ms; idle polling: '
          f'{best[2] * 1e3:.1f} ms of CPU per second')


if __name__ == '__main__':
    main()
