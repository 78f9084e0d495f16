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

"""Quantities with unit suffixes, read into SI at the edges (test programs, the command line).

A plain number is already SI; a string may carry a unit suffix: ``to_si("0.5 mm", "length") -> 5e-4``.
Suffixes are case-sensitive, the space is optional, ``*``, ``·`` or ``.`` may mark a product
(``243 kN*s/m``). Temperatures stay in degC (K is converted to degC); every other dimension comes out
in SI. Dimension ``'number'`` takes a bare number only. One table serves programs and the CLI, so a
unit accepted in one is accepted in the other.
"""
from __future__ import annotations

import math
import re

# dimension -> {suffix: factor to SI}; temperature: {suffix: offset to degC}
UNITS = {
    'length': {'m': 1.0, 'cm': 1e-2, 'mm': 1e-3, 'um': 1e-6, 'µm': 1e-6},
    'velocity': {'m/s': 1.0, 'mm/s': 1e-3, 'um/s': 1e-6, 'µm/s': 1e-6},
    'force': {'N': 1.0, 'kN': 1e3, 'MN': 1e6, 'mN': 1e-3},
    'frequency': {'Hz': 1.0, 'kHz': 1e3, 'mHz': 1e-3},
    'time': {'s': 1.0, 'ms': 1e-3, 'us': 1e-6, 'µs': 1e-6, 'min': 60.0, 'h': 3600.0},
    'stiffness': {'N/m': 1.0, 'N/mm': 1e3, 'kN/m': 1e3, 'kN/mm': 1e6, 'MN/m': 1e6},
    'damping': {'Ns/m': 1.0, 'kNs/m': 1e3, 'Ns/mm': 1e3},
    'stiffness2': {'N/m^2': 1.0, 'N/mm^2': 1e6, 'kN/mm^2': 1e9},
    'stiffness3': {'N/m^3': 1.0, 'N/mm^3': 1e9, 'kN/mm^3': 1e12},
    'stiffness5': {'N/m^5': 1.0, 'N/mm^5': 1e15, 'kN/mm^5': 1e18},
    'slowness': {'s/m': 1.0, 's/mm': 1e3},
    'force_rate': {'N/s': 1.0, 'kN/s': 1e3},
    'temperature': {'degC': 0.0, 'C': 0.0, '°C': 0.0, 'K': -273.15},
    'temperature_difference': {'K': 1.0, 'mK': 1e-3},    # an uncertainty or a step: no offset
    'number': {},
}
_QUANTITY = re.compile(r'^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$')


def dimension_of(unit: str) -> str | None:
    """The dimension a unit suffix belongs to ('kN/mm' -> 'stiffness'), None if it is not known."""
    return next((dim for dim, table in UNITS.items() if unit in table), None)


def to_si(value, dimension: str) -> float:
    """Value of ``value`` (a number, already SI, or a string with a unit suffix of ``dimension``) in SI.

    Raises ValueError with a short reason naming the input (the caller adds which field it was), also for
    values that are not finite (YAML's .inf and .nan, or a number too large for a float).
    """
    if dimension not in UNITS:
        raise ValueError(f'unknown dimension {dimension!r}; known: {", ".join(UNITS)}')
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ValueError(f'expected a {dimension}, got {value!r}')
    if not isinstance(value, str):
        return _finite(value, value, dimension)
    m = _QUANTITY.match(value)
    if not m:
        raise ValueError(f'cannot read a number from {value!r} (expected a {dimension})')
    number = _finite(m.group(1), value, dimension)
    unit = m.group(2).replace('*', '').replace('·', '').replace('.', '')
    if not unit:
        return number
    table = UNITS[dimension]
    if unit not in table:
        dim = dimension_of(unit)
        allowed = f'use one of: {", ".join(table)}' if table else 'a bare number, no unit'
        if dim is None:
            raise ValueError(f'unknown unit {unit!r} in {value!r} ({allowed})')
        raise ValueError(f'{value!r} is a {dim}, expected a {dimension} ({allowed})')
    if dimension == 'temperature':
        return number + table[unit]
    return _finite(number * table[unit], value, dimension)


def _finite(number, given, dimension: str) -> float:
    """float(number), or ValueError if it is not finite (or too large for a float)."""
    try:
        x = float(number)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x):
        raise ValueError(f'must be a finite {dimension}, got {given!r}')
    return x


# a model parameter's scale (rubber_rig.models.catalogue.ParamSpec.scale) -> (factor from SI, unit) of the
# papers' tables (mm, kN, kN/mm), for printed tables and reports
PAPER_UNITS = {'stiffness': (1e-6, 'kN/mm'), 'force': (1e-3, 'kN'), 'length': (1e3, 'mm'),
               'thickness': (1e3, 'mm'), 'damping': (1e-3, 'kNs/m'), 'time': (1.0, 's'), 'order': (1.0, '-'),
               'k2': (1e-9, 'kN/mm^2'), 'k3': (1e-12, 'kN/mm^3'), 'k5': (1e-18, 'kN/mm^5'),
               'slowness': (1e-3, 's/mm'), 'frac_alpha': (1.0, 'SI'), 'frac_beta': (1.0, 'SI'),
               'delay': (1e3, 'ms')}
