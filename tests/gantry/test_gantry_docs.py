"""The README's and docs/hardware.md's gantry lines work as written (issue 23, item 10).

Each command line of the docs is read from the file itself: its PATH line must find the
executables, every calibration it names must exist and load, every replay onto the gantry
must be a step by step one (resets included), the dry run and gantry_node must run.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import shlex
import signal
import subprocess
import time

import pytest

from conftest import child_env
from grbl_emulator import GrblEmulator
from growspace_gantry import calibration
from growspace_sim.replay.cli import build_parser
from test_gantry_node import RIG

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / 'README.md', ROOT / 'docs' / 'hardware.md']


def code_lines(path: Path) -> list[str]:
    """The command lines of a markdown file's fenced blocks (continuations joined, comments
    dropped)."""
    out, block, joined = [], False, ''
    for line in path.read_text(encoding='utf-8').splitlines():
        if line.startswith('```'):
            block = not block
            continue
        if not block:
            continue
        joined += line.split('  #')[0].rstrip()
        if joined.endswith('\\'):
            joined = joined[:-1] + ' '
            continue
        if joined.strip():
            out.append(joined.strip())
        joined = ''
    return out


def readme_path() -> list[Path]:
    """The directories the README's shell set-up (``eval "$(./run.sh env)"``) puts first on
    PATH, as ``./run.sh env`` prints them here."""
    assert 'eval "$(./run.sh env)"' in code_lines(ROOT / 'README.md')
    printed = subprocess.run(['bash', str(ROOT / 'run.sh'), 'env'], capture_output=True,
                             text=True, timeout=600, check=True).stdout
    line = next(x for x in printed.splitlines() if x.startswith('export PATH='))
    value = line.split('=', 1)[1].strip('"')
    return [Path(p) for p in value.split(':') if p != '$PATH']


def lines_of(program: str) -> list[str]:
    return [x for doc in DOCS for x in code_lines(doc) if x.split()[0] == program]


def test_the_readme_path_line_finds_every_gantry_program() -> None:
    dirs = readme_path()
    for program in ('gantry_node', 'growspace-gantry-gcode', 'sim_node', 'teleop'):
        assert any(os.access(d / program, os.X_OK) for d in dirs), (program, dirs)


def test_run_sh_puts_the_gantry_programs_on_path() -> None:
    dirs = [str(d) for d in readme_path()]
    assert str(ROOT / 'install' / 'growspace_gantry' / 'lib' / 'growspace_gantry') in dirs


def test_every_calibration_the_docs_name_exists_and_loads() -> None:
    named = [m.group(1) for x in lines_of('gantry_node')
             for m in re.finditer(r'calibration:=(\S+)', x)]
    assert named
    for path in named:
        calibration.load(path.replace('$PWD', str(ROOT)))


def test_every_replay_onto_the_gantry_sends_the_resets() -> None:
    """A replay paced by steps goes step by step (each episode's reset, then its commands);
    ``--only light/command`` would drop the resets."""
    replays = [x for x in lines_of('growspace-replay') if ' play ' in x and 'step' in x]
    assert replays
    for line in replays:
        line = line.replace('BAG', str(ROOT / 'bags' / 'oracle_control_hard.mcap'))
        args = build_parser().parse_args(shlex.split(line)[1:])  # checks the bag exists
        assert args.step_period is not None and args.topics is None, line


def test_the_dry_run_runs_as_written(tmp_path) -> None:
    env = {**child_env(), 'PATH': os.pathsep.join([*map(str, readme_path()),
                                                   os.environ['PATH']])}
    for line in lines_of('growspace-gantry-gcode'):
        line = line.replace('BAG', 'bags/oracle_control_hard.mcap')
        done = subprocess.run(shlex.split(line), cwd=ROOT, env=env, capture_output=True,
                              text=True, timeout=60)
        assert done.returncode == 0, (line, done.stderr)
        assert '$J=G21G53' in done.stdout and done.stdout.rstrip().endswith('M5')


@pytest.mark.parametrize('line', lines_of('gantry_node'))
def test_gantry_node_runs_as_written(tmp_path, line) -> None:
    """The documented command line, on an emulated controller: it connects, reads ``$$`` and
    stops on SIGINT with the lamp off."""
    with GrblEmulator(RIG, speedup=40.0, link_dir=tmp_path) as grbl:
        argv = shlex.split(line.replace('/dev/ttyUSB0', grbl.port).replace(
            'bags/hw.mcap', str(tmp_path / 'hw.mcap')).replace('$PWD', str(ROOT)))
        # Never a real serial device: a line without the documented port would open the default.
        assert f'port:={grbl.port}' in argv, line
        env = {**child_env(), 'PATH': os.pathsep.join([*map(str, readme_path()),
                                                       os.environ['PATH']])}
        proc = subprocess.Popen(argv, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
        try:
            deadline = time.monotonic() + 90.0  # its start-up on a loaded machine
            # Ready: the settings read and checked, then the lamp-off line, its first.
            while 'M5' not in grbl.lines and time.monotonic() < deadline \
                    and proc.poll() is None:
                time.sleep(0.05)
            assert '$$' in grbl.lines and 'M5' in grbl.lines, proc.poll()
        finally:
            proc.send_signal(signal.SIGINT)
            out = proc.communicate(timeout=20)[0]
        assert proc.returncode == 0, out
        assert grbl.spindle[0] == 'M5' and not grbl.coolant


def test_the_hardware_pages_parameter_table_is_the_declaration() -> None:
    # Regenerate with: python -m growspace_gantry.settings
    from growspace_gantry.settings import GantryParams
    from growspace_sim.core import schema

    table = schema.markdown_table(GantryParams)
    assert table in (ROOT / 'docs' / 'hardware.md').read_text(encoding='utf-8'), \
        'docs/hardware.md parameter table differs from GantryParams'
