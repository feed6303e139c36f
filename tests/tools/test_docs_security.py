"""Where users load files that run code when loaded, the docs say so (issue 24 item 11)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _words(text: str) -> str:
    return ' '.join(text.replace('`', '').split())


def test_growspace_compare_help_says_policy_files_run_code(capsys) -> None:
    from growspace_sim.learn import evaluate_policies  # noqa: PLC0415  (no torch needed)

    with pytest.raises(SystemExit):
        evaluate_policies.main(['--help'])
    assert 'pickle that runs code when loaded' in _words(capsys.readouterr().out)
    assert 'runs code it contains' in _words(evaluate_policies.__doc__)


@pytest.mark.parametrize('doc', ['README.md', 'docs/baselines.md',
                                 'src/growspace_sim/growspace_sim/learn/__init__.py',
                                 'src/growspace_sim/growspace_sim/learn/train.py'])
def test_where_policy_files_are_documented_they_are_called_pickles(doc: str) -> None:
    text = _words((ROOT / doc).read_text())
    assert 'pickle' in text and 'runs code it contains' in text, doc
