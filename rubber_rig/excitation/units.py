"""Quantities in test programs: plain numbers are SI; strings may carry a unit suffix ("0.5 mm", "14 Hz")."""
import math
import re

# unit suffix -> (dimension, factor to SI)
_UNITS = {
    'm': ('length', 1.0), 'mm': ('length', 1e-3), 'um': ('length', 1e-6), 'µm': ('length', 1e-6),
    'Hz': ('frequency', 1.0), 'kHz': ('frequency', 1e3),
    's': ('time', 1.0), 'ms': ('time', 1e-3), 'min': ('time', 60.0),
    'm/s': ('velocity', 1.0), 'mm/s': ('velocity', 1e-3), 'um/s': ('velocity', 1e-6),
    'N': ('force', 1.0), 'kN': ('force', 1e3),
}
_QUANTITY = re.compile(r'^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-zµ/]*)\s*$')


def to_si(value, dimension: str) -> float:
    """Convert a number (already SI) or a string with a unit suffix of `dimension` to an SI float.

    Raises ValueError with a short reason (the caller adds which block/field), also for values that are not
    finite (YAML's .inf and .nan, or a number too large for a float): no quantity in a program may be."""
    if isinstance(value, bool):
        raise ValueError(f'expected a {dimension}, got {value!r}')
    if isinstance(value, (int, float)):
        return _finite(value, value, dimension)
    if not isinstance(value, str):
        raise ValueError(f'expected a {dimension}, got {value!r}')
    m = _QUANTITY.match(value)
    if not m:
        raise ValueError(f'cannot read {value!r} as a {dimension}')
    number, unit = _finite(m.group(1), value, dimension), m.group(2)
    if not unit:
        return number
    if unit not in _UNITS or _UNITS[unit][0] != dimension:
        allowed = ', '.join(u for u, (d, _) in _UNITS.items() if d == dimension)
        raise ValueError(f'unit {unit!r} is not a {dimension} (use one of: {allowed})')
    return _finite(number * _UNITS[unit][1], value, dimension)


def _finite(number, given, dimension: str) -> float:
    """float(number), or ValueError if it is not finite (or too large for a float)."""
    try:
        x = float(number)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x):
        raise ValueError(f'must be a finite {dimension}, got {given!r}')
    return x
