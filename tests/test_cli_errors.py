"""Console programs answer a missing extra or a closed pipe with a sentence, not a traceback."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from growspace_sim import learn


def _hide(monkeypatch: pytest.MonkeyPatch, *names: str) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, 'find_spec',
                        lambda name, *a: None if name in names else real(name, *a))


def test_growspace_train_without_torch_names_the_extra(monkeypatch, capsys) -> None:
    _hide(monkeypatch, 'torch', 'stable_baselines3')
    assert learn.train_main(['--help']) == 2
    err = capsys.readouterr().err
    assert err.strip() == ('growspace-train: needs the learn extra (torch, stable_baselines3 not '
                           'installed): pip install -r requirements-learn.txt')


def test_growspace_compare_of_a_run_without_torch_names_the_extra(monkeypatch, capsys,
                                                                  tmp_path: Path) -> None:
    from growspace_sim.learn import evaluate_policies

    _hide(monkeypatch, 'torch', 'stable_baselines3')
    (tmp_path / 'run.json').write_text(json.dumps({'env': 'GrowSpace/Control-Easy-v0'}))
    assert evaluate_policies.main(['--run', str(tmp_path)]) == 2
    assert 'needs the learn extra (torch, stable_baselines3 not installed)' in \
        capsys.readouterr().err


def test_gcode_into_a_closed_pipe_stops_quietly() -> None:
    # `growspace-gantry-gcode BAG | head`: the reader leaves after a few lines.
    import subprocess
    import sys

    bag = Path(__file__).resolve().parents[1] / 'bags' / 'oracle_control_easy.mcap'
    if not bag.exists():
        pytest.skip('no sample bags')
    writer = subprocess.Popen([sys.executable, '-m', 'growspace_gantry.gcode', str(bag)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    writer.stdout.readline()
    writer.stdout.close()  # as `head -1` does
    _, err = writer.communicate(timeout=60)
    assert writer.returncode == 0 and b'Traceback' not in err and b'BrokenPipe' not in err, err
