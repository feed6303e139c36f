"""./run.sh, the README's entry point: its help, and a set-up that cannot reach a package index."""

from __future__ import annotations

import os
from pathlib import Path
import re
import shutil
import subprocess

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(args: list[str], cwd: Path, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run(['bash', str(cwd / 'run.sh'), *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300, env={**os.environ, **env})


def test_help_exits_0_and_an_unknown_subcommand_2() -> None:
    shown = _run(['help'], ROOT)
    assert shown.returncode == 0 and './run.sh test' in shown.stdout
    wrong = _run(['tset'], ROOT)
    assert wrong.returncode == 2 and "unknown subcommand 'tset'" in wrong.stderr


@pytest.mark.slow
def test_test_passes_pytests_arguments_through() -> None:
    """A file runs alone; no path runs the whole suite (as CI's ./run.sh test does); -m
    "not slow" the quick tier. (run.sh used to add tests/ to whatever it was given.)"""
    one = _run(['test', 'tests/tools/test_layout.py', '-vv', '-p', 'no:cacheprovider'], ROOT)
    ran = re.findall(r'^(\S+)::\S+ PASSED', one.stdout, re.M)
    assert one.returncode == 0 and ran and set(ran) == {'tests/tools/test_layout.py'}, one.stdout
    collected = {}
    for tier, args in (('all', []), ('tests', ['tests']), ('quick', ['-m', 'not slow'])):
        out = _run(['test', '--collect-only', '-p', 'no:cacheprovider', *args], ROOT)
        assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
        collected[tier] = set(re.findall(r'^(tests/\S+::\S+)$', out.stdout, re.M))
    assert collected['all'] == collected['tests'] and len(collected['all']) > 500
    assert collected['quick'] < collected['all']
    assert 'tests/tools/test_run_sh.py::test_test_passes_pytests_arguments_through' \
        not in collected['quick']
    assert 'tests/tools/test_run_sh.py::test_help_exits_0_and_an_unknown_subcommand_2' \
        in collected['quick']


@pytest.mark.slow
def test_a_set_up_without_a_package_index_says_so_and_leaves_no_half_venv(tmp_path) -> None:
    # A copy of what set-up reads, pointed at an index that refuses at once (loopback port 9).
    for name in ['run.sh', *(p.name for p in ROOT.glob('requirements*.txt'))]:
        shutil.copy(ROOT / name, tmp_path / name)
    out = _run(['build'], tmp_path, PIP_INDEX_URL='http://127.0.0.1:9/simple',
               PIP_CONFIG_FILE=os.devnull, PIP_RETRIES='0', PIP_TIMEOUT='2',
               PIP_NO_CACHE_DIR='1', PIP_FIND_LINKS='')
    assert out.returncode == 1
    assert 'run.sh: pip could not install -r requirements.txt into .venv (is a package index ' \
           'reachable?)' in out.stderr
    assert 'Traceback' not in out.stderr.split('run.sh: pip')[-1]
    assert not (tmp_path / '.venv').exists()
    assert (tmp_path / '.venv.pip.log').is_file()
