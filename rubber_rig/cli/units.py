"""Unit-suffix parsing for command-line input: ``parse_quantity("1mm", "length") -> 0.001`` (SI out).

A bare number is taken as SI. Suffixes (case-sensitive, optional space, ``*``/``.``/``·`` as the
product sign): length m, mm, um, cm; force N, kN, MN, mN; frequency Hz, kHz, mHz; time s, ms, us,
min; stiffness N/m, N/mm, kN/mm, kN/m, MN/m; damping N*s/m, kN*s/m, N*s/mm; temperature degC
(also C, °C; the value stays in degC), K (converted to degC).
"""
from __future__ import annotations

import math
import re

UNITS = {
    'length': {'m': 1.0, 'mm': 1e-3, 'um': 1e-6, 'µm': 1e-6, 'cm': 1e-2},
    'force': {'N': 1.0, 'kN': 1e3, 'MN': 1e6, 'mN': 1e-3},
    'frequency': {'Hz': 1.0, 'kHz': 1e3, 'mHz': 1e-3},
    'time': {'s': 1.0, 'ms': 1e-3, 'us': 1e-6, 'µs': 1e-6, 'min': 60.0},
    'stiffness': {'N/m': 1.0, 'N/mm': 1e3, 'kN/mm': 1e6, 'kN/m': 1e3, 'MN/m': 1e6},
    'damping': {'Ns/m': 1.0, 'kNs/m': 1e3, 'Ns/mm': 1e3},
    'temperature': {'degC': 0.0, 'C': 0.0, '°C': 0.0, 'K': -273.15},   # offsets to degC
}
_NUMBER = re.compile(r'^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$')


def _unit_dimension(unit: str):
    for dim, table in UNITS.items():
        if unit in table:
            return dim
    return None


def parse_quantity(text, dimension: str = None) -> float:
    """Value of ``text`` in SI (temperatures in degC). ``dimension`` ('length', 'force', ...) is checked.

    Raises ValueError naming the input when the number or unit is bad or of another dimension.
    """
    if isinstance(text, (int, float)):
        value, unit = float(text), ''
    else:
        m = _NUMBER.match(str(text))
        if not m:
            raise ValueError(f'cannot read a number from {text!r}')
        value, unit = float(m.group(1)), m.group(2).replace('*', '').replace('·', '').replace('.', '')
    if dimension is not None and dimension not in UNITS:
        raise ValueError(f'unknown dimension {dimension!r}; known: {sorted(UNITS)}')
    if not math.isfinite(value):
        raise ValueError(f'{text!r} is not finite')
    if unit == '':
        return value
    dim = _unit_dimension(unit)
    if dim is None:
        raise ValueError(f'unknown unit {unit!r} in {text!r}')
    if dimension is not None and dim != dimension:
        raise ValueError(f'{text!r} is a {dim}, expected a {dimension}')
    if dim == 'temperature':
        return value + UNITS[dim][unit]
    return value * UNITS[dim][unit]
