"""Set-up: the ROS 2 wheels' CMake exports point at the venv's own headers, and only there."""

from __future__ import annotations

import importlib.util
from pathlib import Path
import sys

import pytest

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location('fix_ros_wheel_cmake',
                                              ROOT / 'scripts' / 'fix_ros_wheel_cmake.py')
fix = importlib.util.module_from_spec(spec)
spec.loader.exec_module(fix)

EXPORT = ('set_target_properties(x PROPERTIES INTERFACE_INCLUDE_DIRECTORIES '
          '"${_IMPORT_PREFIX}/include/pkg;/opt/python/cp311-cp311/include/python3.11;'
          '/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include")\n')


@pytest.mark.parametrize(('text', 'expected'), [
    (EXPORT, EXPORT.replace('/opt/python/cp311-cp311/include/python3.11', '/v/include')
     .replace('/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include',
              '/v/np')),
    ('/opt/python/cp312-cp312/include/python3.12 '
     '/opt/python/cp312-cp312/lib/python3.12/site-packages/numpy/core/include',
     '/v/include /v/np'),
    ('no build image path here', 'no build image path here'),
])
def test_rewrite_replaces_both_build_image_paths(text: str, expected: str) -> None:
    assert fix.rewrite(text, '/v/include', '/v/np') == expected


def test_fix_venv_changes_only_cmake_files_under_share_and_is_idempotent(tmp_path: Path) -> None:
    target = tmp_path / 'share' / 'std_msgs' / 'cmake' / 'export.cmake'
    target.parent.mkdir(parents=True)
    target.write_text(EXPORT)
    elsewhere = tmp_path / 'lib' / 'other.cmake'
    elsewhere.parent.mkdir()
    elsewhere.write_text(EXPORT)
    notes = tmp_path / 'share' / 'std_msgs' / 'README.txt'
    notes.write_text(EXPORT)
    assert fix.fix_venv(tmp_path, '/v/include', '/v/np') == [target]
    assert '/opt/python' not in target.read_text() and '/v/np' in target.read_text()
    assert elsewhere.read_text() == EXPORT and notes.read_text() == EXPORT
    assert fix.fix_venv(tmp_path, '/v/include', '/v/np') == []


def test_bad_usage_names_what_is_expected(tmp_path: Path, capsys) -> None:
    assert fix.main([str(tmp_path)]) == 2
    assert 'VENV' in capsys.readouterr().err


@pytest.mark.skipif(sys.prefix == sys.base_prefix, reason='not running in a venv')
def test_this_venv_was_fixed() -> None:
    exports = list((Path(sys.prefix) / 'share').rglob('*.cmake'))
    if not exports:
        pytest.skip('no ROS 2 wheels in this venv')
    assert not [p for p in exports if '/opt/python/' in p.read_text()]
