"""Parameters: config/growspace.yaml mirrors SimConfig and NodeParams; ROS CLI parsing."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from growspace_sim.core import schema
from growspace_sim.core.config import SimConfig
from growspace_sim.node import params
from growspace_sim.node.params import NodeParams, ParamError

ROOT = Path(__file__).resolve().parents[2]
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


# ---------------------------------------------------------- descriptors (ros2 param describe)
BOUNDS = {f.name: p.bounds for f, p in schema.declared(SimConfig) if p.bounds is not None}


@pytest.mark.parametrize('name', sorted(BOUNDS))
def test_every_bound_is_what_simconfig_enforces(name: str) -> None:
    bounds = BOUNDS[name]
    below = bounds.low if bounds.low_open else bounds.low - (1 if bounds.integer else 1e-6)
    for bad in (below, bounds.high * 2 + 1):
        if bad == bounds.sentinel:
            continue
        value = (bad,) if name == 'digits' else bad  # each digit is bounded
        with pytest.raises(ValueError, match=f'^(each of )?{name} must be in .*got {bad!r}'):
            SimConfig(**{name: value})


def test_every_number_parameter_has_a_range() -> None:
    for spec in params.specs():
        if isinstance(spec.default, (int, float)) and not isinstance(spec.default, bool):
            assert spec.bounds is not None, spec.name
            assert spec.bounds.sentinel == spec.default or \
                spec.bounds.low <= spec.default <= spec.bounds.high, spec.name


def test_specs_say_ranges_choices_rules_and_when_a_change_applies() -> None:
    by_name = {s.name: s for s in params.specs()}
    density = by_name['light_density']
    assert (density.bounds.low, density.bounds.high, density.bounds.integer) == (1, 100_000, True)
    assert density.when == 'at the next reset' and not density.read_only('lockstep')
    width = by_name['light_width']
    assert width.rules == ('greater than 0; '
                           'light_width_min <= light_width <= light_width_max')
    assert by_name['challenge'].rules == ('one of control, find_plant, fairness, shape; or '
                                          'module:attribute naming a Task of your own (loaded '
                                          'on first use)')
    assert by_name['setting'].rules == 'one of easy, hard'
    assert by_name['mode'].rules == 'one of lockstep, realtime'
    assert by_name['image_size'].bounds.sentinel == 0
    seed = by_name['seed']
    assert (seed.bounds.low, seed.bounds.sentinel) == (0, -1) and seed.read_only('realtime')
    rate = by_name['rate_hz']
    assert rate.read_only('lockstep') and not rate.read_only('realtime')
    assert not by_name['auto_reset'].read_only('lockstep')
    for name in ('mode', 'record_path', 'frame_id', 'image_frame_id'):
        assert by_name[name].read_only('realtime') and 'read-only' in by_name[name].when


@pytest.mark.parametrize('name,value,message', [
    ('light_density', -5, r'light_density must be in \[1, 100000\], got -5'),
    ('rate_hz', 0.0, r'rate_hz must be in \]0.0, 10000.0\], got 0.0'),
    ('image_size', 4, r'image_size must be in \[8, 1024\] or 0, got 4'),
    ('seed', -2, r'seed must be in \[0, 9223372036854775807\] or -1, got -2'),
])
def test_a_value_out_of_range_is_refused_before_ros_sees_it(name, value, message) -> None:
    spec = next(s for s in params.specs() if s.name == name)
    with pytest.raises(ParamError, match=message):
        params.check_type(spec, value)


def test_a_node_without_runtime_changes_shows_every_parameter_read_only() -> None:
    specs = params.specs_of(SimConfig, NodeParams, runtime=False)
    assert all(s.read_only('realtime') and s.when == 'at start-up (read-only)' for s in specs)
    assert next(s for s in specs if s.name == 'light_density').bounds == \
        BOUNDS['light_density']  # the ranges still show


# ------------------------------------------------------------ one declaration, every view of it
README = ROOT / 'README.md'


def test_the_readme_table_is_the_declaration() -> None:
    # Regenerate with: python -m growspace_sim.node.params --markdown
    table = schema.markdown_table(SimConfig, NodeParams)
    assert table in README.read_text(), 'README parameter table differs from the declarations'
    assert table.count('\n') == len(params.specs()) + 1


def test_every_declaration_says_what_it_means() -> None:
    from growspace_camera.settings import CameraParams
    from growspace_gantry.settings import GantryParams
    from growspace_sim.node.view_node import ViewParams

    for cls in (SimConfig, NodeParams, GantryParams, ViewParams, CameraParams):
        for field, declaration in schema.declared(cls):
            assert declaration.doc and not declaration.doc.endswith('.'), field.name
            if isinstance(field.default, float):
                assert declaration.unit, f'{cls.__name__}.{field.name} has no unit'
        assert {f.name for f, _ in schema.declared(cls)} == \
            {f.name for f in dataclasses.fields(cls)}, f'{cls.__name__}: undeclared fields'


@pytest.mark.parametrize(('cls', 'values', 'message'), [
    ('GantryParams', {'baud': 0}, r'^baud must be in \[1, 4000000\], got 0\.$'),
    ('GantryParams', {'port': ''}, r"^port must be a serial device path, got ''\.$"),
    ('GantryParams', {'mode': 'x'}, r"^mode must be one of \('lockstep', 'realtime'\), got 'x'"),
    ('ViewParams', {'view_size': 8}, r'^view_size must be in \[16, 4096\], got 8\.$'),
    ('ViewParams', {'foxglove_port': 70000}, r'^foxglove_port must be in \[0, 65535\]'),
    ('NodeParams', {'frame_id': 'a b'}, r'^frame_id must be a frame name of letters'),
    ('NodeParams', {'auto_reset': 1}, r'^auto_reset must be a bool \(true or false\), got 1'),
])
def test_every_node_settings_class_validates_from_its_declarations(cls, values, message) -> None:
    from growspace_gantry.settings import GantryParams
    from growspace_sim.node.view_node import ViewParams

    settings = {'GantryParams': GantryParams, 'ViewParams': ViewParams,
                'NodeParams': NodeParams}[cls]
    with pytest.raises(ParamError, match=message):
        settings(**values)
