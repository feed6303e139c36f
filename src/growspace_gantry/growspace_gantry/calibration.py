"""The calibration file: chamber metres (REP-103, the chamber frame) -> GRBL machine millimetres.

It is the only place that maps one to the other. Per axis, ``machine_mm = offset_mm + direction
* mm_per_m * chamber_m`` within ``[min_mm, max_mm]``. Three roles:

- ``x``: the light rail (chamber x, the beam or spot centre), required;
- ``z``: the spotlight centre height (shape challenge), optional;
- ``size``: the lamp's distance to the lit plane. A lamp of full beam angle ``a`` at distance
  ``d`` lights a width ``2 d tan(a/2)`` (beam) or a disc of radius ``d tan(a/2)`` (spotlight),
  so this axis realises the light's width or radius. Optional: without it the lamp lights a
  fixed ``fixed_size_m`` (its width, or its spot diameter) and the driver says so once.

Loading validates every key and names the key, the value and what is allowed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any

import yaml

from growspace_sim.core.light import Light

ROLES = ('x', 'z', 'size')


class CalibrationError(ValueError):
    """A calibration key is missing or invalid, or it does not fit the machine's settings."""


class TargetError(ValueError):
    """A light that the machine cannot reach: never sent to the controller."""


@dataclass(frozen=True)
class AxisMap:
    """One chamber quantity on one machine axis."""

    axis: str  # GRBL axis letter, X, Y or Z
    mm_per_m: float  # machine mm per chamber metre (> 0)
    offset_mm: float  # machine coordinate of chamber value 0 [mm]
    direction: int  # +1: the machine coordinate grows with the chamber value; -1: it falls
    min_mm: float  # travel limits the driver never commands beyond [mm]
    max_mm: float

    def to_machine(self, value_m: float) -> float:
        return self.offset_mm + self.direction * self.mm_per_m * value_m

    def to_chamber(self, machine_mm: float) -> float:
        return (machine_mm - self.offset_mm) / (self.direction * self.mm_per_m)

    def reachable(self, machine_mm: float) -> bool:
        return self.min_mm <= machine_mm <= self.max_mm


@dataclass(frozen=True)
class Calibration:
    """A rig's geometry, speeds and lamp (``config/gantry.yaml``)."""

    x: AxisMap
    z: AxisMap | None
    size: AxisMap | None
    beam_angle_deg: float  # full beam angle of the lamp [deg]
    fixed_size_m: float  # lit width (beam) or spot diameter without a size axis [m]
    feed_mm_min: float  # jog feed rate [mm/min]
    lamp_max_s: float  # S value of full lamp power (GRBL's $30)
    position_tolerance_mm: float  # a move is done when every axis is this close [mm]

    @property
    def half_angle_tan(self) -> float:
        return math.tan(math.radians(self.beam_angle_deg) / 2.0)

    def axes(self) -> dict[str, AxisMap]:
        """Role -> axis map, for the roles this rig has."""
        return {role: m for role in ROLES if (m := getattr(self, role)) is not None}

    def to_machine(self, light: Light) -> dict[str, float]:
        """Machine target [mm] per axis letter of a light in the chamber frame.

        Raises:
            TargetError: naming the quantity, its value in m and mm, and the travel limits.
        """
        values = {'x': light.x}
        if self.z is not None and light.spot:
            values['z'] = light.z
        if self.size is not None:
            values['size'] = (light.radius if light.spot else 0.5 * light.width) \
                / self.half_angle_tan
        target = {}
        for role, value in values.items():
            axis = getattr(self, role)
            mm = axis.to_machine(value)
            if not (math.isfinite(mm) and axis.reachable(mm)):
                raise TargetError(
                    f'{role} = {value!r} m is {mm:.3f} mm on axis {axis.axis}, outside its travel '
                    f'[{axis.min_mm}, {axis.max_mm}] mm (calibration {role}.min_mm/max_mm)')
            target[axis.axis] = mm
        return target

    def to_light(self, position_mm: Mapping[str, float], commanded: Light) -> Light:
        """The light a reported machine position realises (``commanded`` fills what no axis
        carries: the spot height without a z axis)."""
        light = commanded.copy()
        light.x = self.x.to_chamber(position_mm[self.x.axis])
        if self.z is not None and light.spot:
            light.z = self.z.to_chamber(position_mm[self.z.axis])
        if self.size is not None:
            reach = self.size.to_chamber(position_mm[self.size.axis]) * self.half_angle_tan
            light.radius, light.width = (reach, commanded.width) if light.spot else \
                (commanded.radius, 2.0 * reach)
        elif light.spot:
            light.radius = 0.5 * self.fixed_size_m
        else:
            light.width = self.fixed_size_m
        return light

    def check_settings(self, settings: Mapping[int, float]) -> list[str]:
        """What in the machine's ``$$`` settings contradicts this calibration (empty: none).

        GRBL's max rates are $110-$112 [mm/min], max travel $130-$132 [mm]; with soft limits
        ($20=1) machine coordinates lie in [-travel, 0]; $30 is the S of full power; $32=1 is
        laser mode, without which every lamp change stops the motion.
        """
        problems = []

        def need(number: int) -> float | None:
            if number not in settings:
                problems.append(f"${number} is missing from the controller's $$ report")
                return None
            return settings[number]
        if need(32) not in (None, 1.0):
            problems.append(f'$32 = {settings[32]:g} (laser mode off): lamp changes would stop '
                            f'every move; send $32=1 to the controller once')
        max_s = need(30)
        if max_s is not None and max_s != self.lamp_max_s:
            problems.append(f'calibration lamp_max_s = {self.lamp_max_s:g} differs from $30 = '
                            f'{max_s:g} (the S of full power)')
        soft = need(20) == 1.0
        for role, axis in self.axes().items():
            i = 'XYZ'.index(axis.axis)
            rate, travel = need(110 + i), need(130 + i)
            if rate is not None and self.feed_mm_min > rate:
                problems.append(f'calibration feed_mm_min = {self.feed_mm_min:g} exceeds '
                                f'${110 + i} = {rate:g} mm/min (axis {axis.axis})')
            if travel is None:
                continue
            if axis.max_mm - axis.min_mm > travel:
                problems.append(f'calibration {role}: travel [{axis.min_mm:g}, {axis.max_mm:g}] '
                                f'mm is longer than ${130 + i} = {travel:g} mm')
            if soft and not (-travel <= axis.min_mm and axis.max_mm <= 0.0):
                problems.append(f'calibration {role}: [{axis.min_mm:g}, {axis.max_mm:g}] mm is '
                                f"outside GRBL's soft-limit space [-{travel:g}, 0] mm "
                                f'(${130 + i}, $20=1)')
        return problems


def _number(data: Mapping[str, Any], key: str, where: str, low: float = -math.inf,
            high: float = math.inf, low_open: bool = False) -> float:
    if key not in data:
        raise CalibrationError(f'{where}{key} is missing')
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value > high or value < low \
            or (low_open and value == low):
        bound = f'{"]" if low_open else "["}{low:g}, {high:g}]'
        raise CalibrationError(f'{where}{key} = {value!r} must be a finite number in {bound}')
    return float(value)


def _axis(data: Any, role: str) -> AxisMap | None:
    if data is None and role != 'x':
        return None
    if not isinstance(data, Mapping):
        raise CalibrationError(f'{role} = {data!r} must be a mapping of axis, mm_per_m, '
                               f'offset_mm, direction, min_mm, max_mm'
                               + ('' if role == 'x' else ', or null (no such axis)'))
    unknown = sorted(set(data) - {'axis', 'mm_per_m', 'offset_mm', 'direction', 'min_mm',
                                  'max_mm'})
    if unknown:
        raise CalibrationError(f'{role}: unknown key(s) {unknown}')
    axis = data.get('axis')
    if axis not in ('X', 'Y', 'Z'):
        raise CalibrationError(f'{role}.axis = {axis!r} must be X, Y or Z')
    direction = data.get('direction')
    if direction not in (1, -1) or isinstance(direction, bool):
        raise CalibrationError(f'{role}.direction = {direction!r} must be 1 or -1')
    where = f'{role}.'
    low, high = _number(data, 'min_mm', where), _number(data, 'max_mm', where)
    if not low < high:
        raise CalibrationError(f'{role}.min_mm ({low:g}) must be lower than {role}.max_mm '
                               f'({high:g})')
    return AxisMap(axis, _number(data, 'mm_per_m', where, 0.0, low_open=True),
                   _number(data, 'offset_mm', where), direction, low, high)


def from_dict(data: Any) -> Calibration:
    """Validate a parsed calibration file.

    Raises:
        CalibrationError: naming the key, its value and what is allowed.
    """
    if not isinstance(data, Mapping):
        raise CalibrationError(f'the calibration must be a mapping, got {type(data).__name__}')
    keys = {'x', 'z', 'size', 'beam_angle_deg', 'fixed_size_m', 'feed_mm_min', 'lamp_max_s',
            'position_tolerance_mm'}
    unknown = sorted(set(data) - keys)
    if unknown:
        raise CalibrationError(f'unknown key(s) {unknown}; allowed: {sorted(keys)}')
    axes = {role: _axis(data.get(role), role) for role in ROLES}
    letters = [a.axis for a in axes.values() if a is not None]
    if len(set(letters)) != len(letters):
        raise CalibrationError(f'x, z and size must use different machine axes, got {letters}')
    return Calibration(
        **axes,
        beam_angle_deg=_number(data, 'beam_angle_deg', '', 0.0, 170.0, low_open=True),
        fixed_size_m=_number(data, 'fixed_size_m', '', 0.0, low_open=True),
        feed_mm_min=_number(data, 'feed_mm_min', '', 0.0, low_open=True),
        lamp_max_s=_number(data, 'lamp_max_s', '', 0.0, low_open=True),
        position_tolerance_mm=_number(data, 'position_tolerance_mm', '', 0.0, low_open=True))


def load(path: str | Path) -> Calibration:
    """Read and validate ``config/gantry.yaml`` (or another calibration file).

    Raises:
        CalibrationError: the file cannot be read or parsed, or a key is invalid (the message
            starts with the path).
    """
    try:
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
        return from_dict(data)
    except OSError as e:
        raise CalibrationError(f'{path}: cannot read: {e.strerror or e}') from None
    except yaml.YAMLError as e:
        raise CalibrationError(f'{path}: not YAML: {e}') from None
    except CalibrationError as e:
        raise CalibrationError(f'{path}: {e}') from None
