"""The gantry's pure layers: GRBL lines, character counting, the calibration file."""

from __future__ import annotations

import math

import pytest
import yaml

from growspace_gantry import calibration, grbl
from growspace_gantry.main import default_calibration
from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import Light


# --- GRBL lines ------------------------------------------------------------------------------

def test_parse_answers_alarms_and_banner() -> None:
    assert grbl.parse_line('ok') == grbl.Ok()
    assert grbl.parse_line('error:9') == grbl.Error(9)
    assert 'alarm or jog' in grbl.Error(9).meaning
    assert grbl.parse_line('ALARM:1') == grbl.Alarm(1)
    assert 'hard limit' in grbl.Alarm(1).meaning
    assert grbl.parse_line("Grbl 1.1h ['$' for help]") == grbl.Banner('1.1h')
    assert grbl.parse_line("[MSG:'$H'|'$X' to unlock]") == grbl.Message("'$H'|'$X' to unlock")
    assert grbl.parse_line('[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]') == grbl.Feedback(
        'GC', 'G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0')
    assert grbl.parse_line('$110=500.000') == grbl.Setting(110, 500.0)
    assert grbl.parse_line('>G54G20:ok') == grbl.StartupLine('G54G20')
    # An echo or noise is never taken for the answer to a line.
    for noise in ('okay', 'error:x', '<Flying|MPos:0,0,0>', '\x00\x13', 'Grbl'):
        assert isinstance(grbl.parse_line(noise), grbl.Unknown), noise


def test_status_fields_by_name_in_any_order() -> None:
    a = grbl.parse_line('<Idle|MPos:0.000,0.000,0.000|FS:0,0|Pn:PXYZRHS|WCO:0.000,0.000,0.000>')
    b = grbl.parse_line('<Run|WCO:1.000,2.000,3.000|FS:559,500|MPos:4.868,0.000,-2.432|A:S>')
    assert (a.state, a.mpos, a.feed, a.speed) == ('Idle', (0.0, 0.0, 0.0), 0.0, 0.0)
    assert (b.state, b.mpos, b.feed, b.speed, b.fields['A']) == (
        'Run', (4.868, 0.0, -2.432), 559.0, 500.0, 'S')
    hold = grbl.parse_line('<Hold:1|MPos:1.000,0.000,0.000|Bf:15,128|FS:0,0>')
    assert (hold.state, hold.substate, hold.planner_free, hold.rx_free) == ('Hold', 1, 15, 128)
    # $10=0: work position, machine position from the last work offset seen.
    w = grbl.parse_line('<Jog|WPos:1.000,1.000,1.000|FS:100,0>')
    assert w.machine_position(None) is None
    assert w.machine_position((10.0, 0.0, -1.0)) == (11.0, 1.0, 0.0)
    for state in grbl.STATES:
        assert grbl.parse_line(f'<{state}|MPos:0.000,0.000,0.000>').state == state


@pytest.mark.parametrize('line', [
    '<Idle|MPos:-425.000,-300.000|FS:0,0>',  # two coordinates (seen on real GRBL output)
    '<Idle|MPos:-425.000,0.000,-300.000,1.000,2.000,3.000,4.000|FS:0,0>',  # seven
    '<Idle|MPos:-2,75.000,0.000,-300.000|FS:0,0>',  # a comma inserted: -2 has no decimals
    '<Idle|MPos:-425.0000.000,-300.000|FS:0,0>',  # a comma dropped
    '<Idle|MPos:-425.000,0.000,-300.000|FS:1000>',  # FS with one number
    '<Idle|MPos:-425.000,0.000,-300.000|Bf:15>',  # Bf with one count
    '<Idle|MPos:-425.000,0.000,-300.000|WCO:0.000,0.000>',  # WCO: fewer axes than MPos
    '<Idle|FS:0,0>',  # no position at all
    '<Idle|MPos:1.000,0.000,0.000|WPos:1.000,0.000,0.000>',  # both positions
    '<Idle|MPos:1.000,0.000,0.000|MPos:2.000,0.000,0.000>',  # a field twice
    '<Idle|MPos1.000,0.000,0.000>',  # a field without its colon
    '<Idle:0|MPos:1.000,0.000,0.000>',  # a substate on a state that has none
    '<Hold:7|MPos:1.000,0.000,0.000>',  # an unknown substate
    '<Idle|MPos:nan,0.000,0.000>', '<Idle|MPos:1e3,0.000,0.000>',
])
def test_a_status_field_of_the_wrong_count_or_form_makes_the_line_unknown(line) -> None:
    assert isinstance(grbl.parse_line(line), grbl.Unknown)


def test_other_answers_are_checked_whole() -> None:
    for line in ('error:', 'error:9x', 'ALARM:', 'ALARM:3.', '$110=6000x', '$110='):
        assert isinstance(grbl.parse_line(line), grbl.Unknown), line
    assert grbl.alarm_text(3).startswith('ALARM:3 (reset while in motion')
    assert grbl.alarm_text(0).startswith('alarm (no code)')
    assert grbl.alarm_text(None).startswith('alarm (no code)')


def test_lines_we_build() -> None:
    assert grbl.jog_line({'Z': -5.0, 'X': 10.0}, 600) == '$J=G21G53X10.000Z-5.000F600'
    assert grbl.jog_line({'X': -0.0001}, 1000) == '$J=G21G53X0.000F1000'
    assert grbl.lamp_line(750) == 'M3 S750'
    assert grbl.lamp_line(0) == 'M5'
    with pytest.raises(ValueError, match='X = nan mm is not finite'):
        grbl.jog_line({'X': math.nan}, 600)
    with pytest.raises(ValueError, match='feed'):
        grbl.jog_line({'X': 1.0}, 0)
    with pytest.raises(ValueError, match="axis 'A'"):
        grbl.jog_line({'A': 1.0}, 100)
    with pytest.raises(ValueError, match='lamp power'):
        grbl.lamp_line(math.inf)
    assert len(grbl.jog_line({'X': -12345.678, 'Y': -12345.678, 'Z': -12345.678}, 99999)) \
        <= grbl.MAX_LINE_BYTES


def test_character_counting_never_overfills_the_buffer() -> None:
    counter = grbl.CharacterCounter(capacity=20)
    lines = ['$J=G21G53X1F9', 'M3 S100', 'M5']
    assert counter.fits(lines[0])
    counter.sent(lines[0])  # 14 bytes with its newline
    assert counter.used == 14
    assert not counter.fits(lines[1])  # 14 + 8 > 20
    assert counter.fits(lines[2])
    counter.sent(lines[2])
    assert counter.acknowledged() == lines[0]  # answers come in order
    assert counter.used == 3 and counter.pending == 1
    assert counter.acknowledged() == 'M5'
    assert counter.acknowledged() is None  # an ok for nothing of ours changes nothing
    assert counter.used == 0


# --- calibration ---------------------------------------------------------------------------------

def shipped() -> dict:
    with open(default_calibration(), encoding='utf-8') as f:
        return yaml.safe_load(f)


def test_shipped_calibration_reaches_every_light_of_the_default_chamber() -> None:
    cal = calibration.from_dict(shipped())
    cfg = SimConfig()
    w = cfg.chamber_width
    for x in (0.5 * cfg.width_m(cfg.light_width_max), w / 2,
              w - 0.5 * cfg.width_m(cfg.light_width_min)):
        for width in (cfg.width_m(cfg.light_width_min), cfg.width_m(cfg.light_width_max)):
            light = Light(False, x, 0.0, width, 0.0)
            target = cal.to_machine(light)
            back = cal.to_light(target, light)
            assert back.x == pytest.approx(x, abs=1e-12)
            assert back.width == pytest.approx(width, abs=1e-12)
    # Known answer: x 0.42 m -> -845 + 420 mm; width 0.2 m at 90 degrees -> 0.1 m above canopy.
    assert cal.to_machine(Light(False, 0.42, 0.0, 0.2, 0.0)) == pytest.approx(
        {'X': -425.0, 'Z': -300.0})


def test_a_light_beyond_the_travel_is_refused_naming_it() -> None:
    data = shipped()
    data['x']['min_mm'] = -500.0
    cal = calibration.from_dict(data)
    with pytest.raises(calibration.TargetError, match=r'x = 0.1 m is -745.000 mm on axis X, '
                                                       r'outside its travel \[-500.0, -5.0\]'):
        cal.to_machine(Light(False, 0.1, 0.0, 0.2, 0.0))


@pytest.mark.parametrize('path, value, message', [
    (('x', 'axis'), 'A', r"x.axis = 'A' must be X, Y or Z"),
    (('x', 'direction'), 2, r'x.direction = 2 must be 1 or -1'),
    (('x', 'mm_per_m'), 0.0, r'x.mm_per_m = 0.0 must be a finite number in \]0'),
    (('x', 'min_mm'), 10.0, r'x.min_mm \(10\) must be lower than x.max_mm \(-5\)'),
    (('size', 'axis'), 'X', r'x, z and size must use different machine axes'),
    (('beam_angle_deg',), 180.0, r'beam_angle_deg = 180.0 must be a finite number'),
    (('feed_mm_min',), float('nan'), r'feed_mm_min = nan'),
    (('lamp_max_s',), 'high', r"lamp_max_s = 'high'"),
    (('colour',), 'red', r"unknown key\(s\) \['colour'\]"),
])
def test_bad_calibration_names_key_and_value(path, value, message) -> None:
    data = shipped()
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(calibration.CalibrationError, match=message):
        calibration.from_dict(data)


def test_missing_key_and_missing_file(tmp_path) -> None:
    data = shipped()
    del data['x']['offset_mm']
    with pytest.raises(calibration.CalibrationError, match='x.offset_mm is missing'):
        calibration.from_dict(data)
    with pytest.raises(calibration.CalibrationError, match='nope.yaml: cannot read'):
        calibration.load(tmp_path / 'nope.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('x: [1, 2\n')
    with pytest.raises(calibration.CalibrationError, match='bad.yaml: not YAML'):
        calibration.load(bad)


def test_machine_settings_are_checked_against_the_calibration() -> None:
    cal = calibration.from_dict(shipped())
    good = {10: 1, 20: 1, 22: 1, 30: 1000, 32: 1, 110: 5000, 111: 5000, 112: 5000, 130: 900,
            131: 900, 132: 500}
    assert cal.check_settings(good) == []
    problems = cal.check_settings({**good, 32: 0, 30: 255, 110: 500, 132: 200})
    text = '\n'.join(problems)
    assert '$32 = 0 (laser mode off)' in text
    assert 'lamp_max_s = 1000 differs from $30 = 255' in text
    assert 'feed_mm_min = 1000 exceeds $110 = 500 mm/min' in text
    assert 'longer than $132 = 200 mm' in text
    soft = cal.check_settings({**good, 130: 800})  # X reaches -845 mm: beyond -$130
    assert any("outside GRBL's soft-limit space [-800, 0]" in p for p in soft)
    assert '$32 is missing' in '\n'.join(cal.check_settings({}))
