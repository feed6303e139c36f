"""./run.sh, the README's entry point: its help, and a set-up that cannot reach a package index."""

from __future__ import annotations

import os
from pathlib import Path
import shutil
import subprocess

ROOT = Path(__file__).resolve().parents[1]


def _run(args: list[str], cwd: Path, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run(['bash', str(cwd / 'run.sh'), *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300, env={**os.environ, **env})


def test_help_exits_0_and_an_unknown_subcommand_2() -> None:
    shown = _run(['help'], ROOT)
    assert shown.returncode == 0 and './run.sh test' in shown.stdout
    wrong = _run(['tset'], ROOT)
    assert wrong.returncode == 2 and "unknown subcommand 'tset'" in wrong.stderr


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
