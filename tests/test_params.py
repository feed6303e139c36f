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
    assert unset == ['digits'] and '    # digits: []' in YAML.read_text()
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


@pytest.mark.parametrize(('values', 'words'), [
    ({'light_width': 2.0}, ['light_width', '2.0', '1.0']),
    ({'mode': 'fast'}, ['mode', 'fast', 'lockstep']),
    ({'rate_hz': 0}, ['rate_hz', '0']),
    ({'rate_hz': 'abc'}, ['rate_hz', 'abc', 'number']),
    ({'episode_length': 1.5}, ['episode_length', '1.5', 'integer']),
    ({'shading': 7}, ['shading', '7', 'bool']),
    ({'digits': [12]}, ['digits', '12']),
    ({'seed': -5}, ['seed', '-5']),
    ({'no_such': 1}, ['no_such']),
    ({'challenge': 'tennis'}, ['challenge', 'tennis', 'control']),
])
def test_invalid_value_gives_one_clear_line(values: dict, words: list[str]) -> None:
    with pytest.raises(ParamError) as err:
        params.build(values)
    text = str(err.value)
    assert '\n' not in text
    for word in words:
        assert word in text, (word, text)


def test_an_integer_is_accepted_for_a_float_parameter() -> None:
    spec = next(s for s in params.specs() if s.name == 'rate_hz')
    assert params.check_type(spec, 20) == 20.0 and isinstance(params.check_type(spec, 20), float)
    with pytest.raises(ParamError, match='rate_hz'):
        params.check_type(spec, True)


def test_as_values_inverts_build() -> None:
    cfg, node = SimConfig(challenge='shape', digits=(1, 2)), NodeParams(mode='realtime')
    assert params.build(params.as_values(cfg, node)) == (cfg, node)
