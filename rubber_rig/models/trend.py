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


"""Operating-point trends: a coefficient that is a number, or a table c[i][j] with value = sum_ij c[i][j] f^i A^j
(f [Hz], A [m], SI), as seed 004 Eq. 7-12 write K1 and K3; and the checks of element parameters built on them.
"""
from __future__ import annotations

import math
import numbers

import numpy as np


def check_trend(name: str, coeffs):
    """Normalised operating-point coefficient ``coeffs`` of parameter ``name`` (seed 004 Eq. 7-12).

    Parameters
    ----------
    name : str
        Parameter name, for the error message.
    coeffs : float or 2-D nested sequence
        A number (constant, SI), or a table c[i][j] (rows i = powers of f [Hz], columns j = powers of A [m]);
        the coefficient is sum_ij c[i][j] f^i A^j in SI, so c[i][j] has the unit of the coefficient per Hz^i m^j.

    Returns
    -------
    float or tuple of tuple of float
        The number, or the table as a rectangular tuple of tuples.

    Raises
    ------
    ValueError
        Naming ``name``: a non-finite entry, an empty table or row, a ragged or not 2-D table, a non-number.
    """
    if _is_number(coeffs):
        value = float(coeffs)
        if not math.isfinite(value):
            raise ValueError(f'parameter {name} must be finite, got {coeffs!r}')
        return value
    if isinstance(coeffs, (str, bytes)) or not hasattr(coeffs, '__iter__'):
        raise ValueError(f'parameter {name} must be a number or a 2-D table c[i][j] (f^i A^j), got {coeffs!r}')
    rows = []
    for i, row in enumerate(coeffs):
        if _is_number(row) or isinstance(row, (str, bytes)) or not hasattr(row, '__iter__'):
            raise ValueError(f'parameter {name} must be a 2-D table c[i][j] (rows: powers of frequency, columns: '
                             f'powers of amplitude), row {i} is {row!r}')
        values = []
        for j, c in enumerate(row):
            if not _is_number(c) or not math.isfinite(float(c)):
                raise ValueError(f'parameter {name}: entry [{i}][{j}] must be a finite number, got {c!r}')
            values.append(float(c))
        rows.append(tuple(values))
    if not rows or not rows[0]:
        raise ValueError(f'parameter {name}: the table c[i][j] is empty')
    if any(len(r) != len(rows[0]) for r in rows):
        raise ValueError(f'parameter {name}: the table c[i][j] is ragged (row lengths {[len(r) for r in rows]})')
    return tuple(rows)


def _is_number(value) -> bool:
    # bool is an int, but a flag where a stiffness belongs is a mistake
    if isinstance(value, bool):
        return False
    if isinstance(value, numbers.Real):
        return True
    return isinstance(value, np.ndarray) and value.ndim == 0 and np.issubdtype(value.dtype, np.number)


def compile_trend(trend):
    """Evaluation form of a normalised trend: a float, or rows with trailing zeros dropped (so a table without a
    frequency dependence never reads f, which may be unknown, and Horner does no work for zero powers).
    """
    if isinstance(trend, float):
        return trend
    rows = [list(r) for r in trend]
    for r in rows:
        while len(r) > 1 and r[-1] == 0.0:
            r.pop()
    while len(rows) > 1 and rows[-1] == [0.0]:
        rows.pop()
    if len(rows) == 1 and len(rows[0]) == 1:
        return rows[0][0]
    return tuple(tuple(r) for r in rows)


def depends_on_frequency(compiled) -> bool:
    return not isinstance(compiled, float) and len(compiled) > 1


def evaluate_trend(compiled, f, a):
    """Horner's scheme in A (inner) and f (outer): the same multiplications and additions for Python floats and
    numpy arrays, so a streamed sample and the same sample of a batch give the same bits.
    """
    if isinstance(compiled, float):
        return compiled
    acc = None
    for row in reversed(compiled):
        p = row[-1]
        for c in reversed(row[:-1]):
            p = p * a + c
        acc = p if acc is None else acc * f + p
    return acc


def trend_value(coeffs, frequency, amplitude):
    """Value of an operating-point coefficient (seed 004 Eq. 7, 10, 11) at frequency f [Hz] and amplitude A [m].

    Parameters
    ----------
    coeffs : float or 2-D nested sequence
        A number, or c[i][j] with value = sum_ij c[i][j] f^i A^j (SI; see :func:`check_trend`).
    frequency : float, array or None
        f [Hz]; None is allowed when the trend does not depend on f.
    amplitude : float or array
        A [m].

    Returns
    -------
    float or ndarray
        The coefficient (SI) broadcast over ``frequency`` and ``amplitude``; a float if both are scalars.
    """
    compiled = compile_trend(check_trend('coeffs', coeffs))
    if frequency is None:
        if depends_on_frequency(compiled):
            raise ValueError('parameter frequency is required: the trend depends on frequency')
        frequency = math.nan
    scalar = np.ndim(frequency) == 0 and np.ndim(amplitude) == 0
    if scalar:
        return float(evaluate_trend(compiled, float(frequency), float(amplitude)))
    f, a = np.broadcast_arrays(np.asarray(frequency, dtype=float), np.asarray(amplitude, dtype=float))
    return np.asarray(evaluate_trend(compiled, f, a), dtype=float) + np.zeros(f.shape)


def check_positive(name, value, required=False):
    if value is None:
        if required:
            raise ValueError(f'parameter {name} is required')
        return None
    if not _is_number(value) or not (math.isfinite(float(value)) and float(value) > 0.0):
        raise ValueError(f'parameter {name} must be a finite number > 0, got {value!r}')
    return float(value)


def check_finite(name, value):
    if value is None:
        return None
    if not _is_number(value) or not math.isfinite(float(value)):
        raise ValueError(f'parameter {name} must be a finite number, got {value!r}')
    return float(value)
