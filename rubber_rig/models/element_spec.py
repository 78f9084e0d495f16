# Copyright 2026 rubber_rig developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""One element of a model file: its catalogue type, parameter values (SI), fixed names and options, parsed from
its YAML entry with units (errors name the entry and the parameter).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from rubber_rig.units import to_si

from .catalogue import OPERATING_POINT_TYPES, element_type

RESULT_KEYS = ('sigma', 'interval_95', 'relative_sigma', 'budget', 'interval_method', 'interval_note')


@dataclass
class ElementSpec:
    """One element: its catalogue ``type``, parameter ``values`` (SI floats), ``fixed`` names, ``options``."""

    type: str
    values: dict
    fixed: frozenset = frozenset()
    options: dict = field(default_factory=dict)

    @property
    def fittable(self) -> bool:
        return self.type not in OPERATING_POINT_TYPES


def _value(raw, spec, where):
    if isinstance(raw, dict):
        raw = raw.get('value')
    try:
        return to_si(raw, spec.dimension)
    except ValueError as exc:
        raise ValueError(f'{where}: {exc} [{spec.unit}]') from None


def parse_element(entry, where) -> ElementSpec:
    if not isinstance(entry, dict) or 'type' not in entry:
        raise ValueError(f'{where}: expected a mapping with a "type", e.g. {{type: berg, x2: 1.4 mm, f_fmax: 4.6 kN}}')
    entry = dict(entry)
    kind = entry.pop('type')
    for key in RESULT_KEYS:
        entry.pop(key, None)
    fixed = entry.pop('fixed', [])
    if isinstance(fixed, str):
        fixed = [fixed]
    if kind in OPERATING_POINT_TYPES:
        return ElementSpec(kind, _operating_point_values(entry, where), frozenset())
    t = element_type(kind)
    values, options = {}, {}
    for key, raw in entry.items():
        if key in t.options:
            options[key] = _option(key, raw, where)
            continue
        try:
            spec = t.param(key)
        except KeyError:
            raise ValueError(f'{where}: unknown parameter {key!r} of {t.name}; its parameters: '
                             f'{", ".join(p.name for p in t.params)}'
                             + (f'; options: {", ".join(t.options)}' if t.options else '')) from None
        values[key] = _value(raw, spec, f'{where}.{key}')
        if isinstance(raw, dict) and raw.get('fixed'):
            fixed = list(fixed) + [key]
    missing = [p.name for p in t.params if not p.optional and p.name not in values]
    if missing:
        raise ValueError(f'{where}: {t.name} needs {", ".join(missing)}')
    if not values:
        raise ValueError(f'{where}: {t.name} needs at least one of {", ".join(p.name for p in t.params)}')
    bad = sorted(set(fixed) - set(values))
    if bad:
        raise ValueError(f'{where}.fixed: {", ".join(bad)} is not a parameter of this element')
    return ElementSpec(t.name, values, frozenset(fixed), options)


def _option(key, raw, where):
    if key in ('amplitude', 'center', 'reversal_threshold'):
        try:
            return to_si(raw, 'length')
        except ValueError as exc:
            raise ValueError(f'{where}.{key}: {exc}') from None
    return raw


def _operating_point_values(entry, where) -> dict:
    out = {}
    for key, raw in entry.items():
        if key == 'k_odd':
            if not isinstance(raw, (list, tuple)) or not raw:
                raise ValueError(f'{where}.k_odd: expected a list of coefficients (numbers or tables, SI)')
            out[key] = list(raw)
        elif key in ('amplitude', 'reversal_threshold'):
            out[key] = _option(key, raw, where)
        elif key == 'frequency':
            out[key] = to_si(raw, 'frequency')
        else:
            raise ValueError(f'{where}: unknown key {key!r} of operating_point_spring')
    return out
