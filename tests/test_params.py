"""Parameters: config/growspace.yaml mirrors SimConfig and NodeParams; ROS CLI parsing."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from growspace_sim.core.config import SimConfig
from growspace_sim.node import params
from growspace_sim.node.params import NodeParams, ParamError

ROOT = Path(__file__).resolve().parents[1]
YAML = ROOT / 'config' / 'growspace.yaml'


def test_yaml_keys_types_and_defaults_equal_the_dataclasses() -> None:
    doc = yaml.safe_load(YAML.read_text())
    assert list(doc) == ['/**']
    values = doc['/**']['ros__parameters']
    fields = [*dataclasses.fields(SimConfig), *dataclasses.fields(NodeParams)]
    # An empty list is written commented out (ROS cannot type it); unset means the same.
    unset = [f.name for f in fields if f.default == ()]
    assert unset == ['digits'] and f'    # digits: []' in YAML.read_text()
    assert list(values) == [f.name for f in fields if f.name not in unset]
    for field in fields:
        if field.name in unset:
            continue
        default = field.default
        value = values[field.name]
        if isinstance(default, tuple):
            assert value == list(default), field.name
        else:
            assert type(value) is type(default) and value == default, field.name
    assert params.build(values) == (SimConfig(), NodeParams())


def test_yaml_writes_floats_as_floats_and_documents_every_parameter() -> None:
    lines = [ln for ln in YAML.read_text().splitlines() if ln.startswith('    ')]
    assert len(lines) == len(params.specs())
    for line in lines:
        name, rest = line.strip().removeprefix('# ').split(':', 1)
        assert '#' in rest, f'{name} has no description'
        spec = next(s for s in params.specs() if s.name == name)
        if isinstance(spec.default, float):
            assert '.' in rest.split('#')[0], f'{name} must be written as 0.0-style'
    assert params.to_yaml() in YAML.read_text()


def test_descriptions_name_units() -> None:
    described = {s.name: s.description for s in params.specs()}
    assert 'm' in described['chamber_width'].split(';')[0]
    assert described['rate_hz'].startswith('Hz')
    assert all(described.values())


def test_cli_parsing_files_then_overrides(tmp_path: Path) -> None:
    extra = tmp_path / 'extra.yaml'
    extra.write_text('/**:\n  ros__parameters:\n    rate_hz: 5.0\n    seed: 3\n'
                     'other_node:\n  ros__parameters:\n    seed: 99\n'
                     '/ns1/chamber:\n  ros__parameters:\n    challenge: shape\n')
    args = params.parse_ros_args([
        'ignored', '--ros-args', '--params-file', str(YAML), '--params-file', str(extra),
        '-p', 'seed:=11', '-p', 'digits:=[3, 6]', '-p', 'shading:=false', '-r', '__ns:=/ns1',
        '-r', '__node:=chamber', '--log-level', 'debug', '-p', 'frame_id:=lab'])
    assert args.rest == ['ignored'] and args.namespace == '/ns1' and args.node_name == 'chamber'
    cfg, node = params.build(args.params)
    assert (node.rate_hz, node.seed, node.frame_id) == (5.0, 11, 'lab')
    assert cfg.digits == (3, 6) and cfg.shading is False and cfg.challenge == 'shape'


@pytest.mark.parametrize(('argv', 'words'), [
    (['--ros-args', '-p', 'light_width:=2.0'], ['light_width', '2.0', '1.0']),
    (['--ros-args', '-p', 'mode:=fast'], ['mode', 'fast', 'lockstep']),
    (['--ros-args', '-p', 'rate_hz:=0'], ['rate_hz', '0']),
    (['--ros-args', '-p', 'rate_hz:=abc'], ['rate_hz', 'abc', 'number']),
    (['--ros-args', '-p', 'episode_length:=1.5'], ['episode_length', '1.5', 'integer']),
    (['--ros-args', '-p', 'shading:=7'], ['shading', '7', 'bool']),
    (['--ros-args', '-p', 'digits:=[12]'], ['digits', '12']),
    (['--ros-args', '-p', 'seed:=-5'], ['seed', '-5']),
    (['--ros-args', '-p', 'no_such:=1'], ['no_such']),
    (['--ros-args', '-p', 'challenge:=tennis'], ['challenge', 'tennis', 'control']),
])
def test_invalid_value_gives_one_clear_line(argv: list[str], words: list[str]) -> None:
    with pytest.raises(ParamError) as err:
        params.build(params.parse_ros_args(argv).params)
    text = str(err.value)
    assert '\n' not in text
    for word in words:
        assert word in text, (word, text)


@pytest.mark.parametrize('argv', [
    ['--ros-args', '-r', 'light/command:=/x'],
    ['--ros-args', '--enclave', '/e'],
    ['--ros-args', '-p', 'seed'],
    ['--ros-args', '-p'],
    ['--ros-args', '--params-file', '/no/such/file.yaml'],
])
def test_unsupported_or_broken_arguments_are_errors(argv: list[str]) -> None:
    with pytest.raises(ParamError):
        params.parse_ros_args(argv)


def test_as_values_inverts_build() -> None:
    cfg, node = SimConfig(challenge='shape', digits=(1, 2)), NodeParams(mode='realtime')
    assert params.build(params.as_values(cfg, node)) == (cfg, node)
