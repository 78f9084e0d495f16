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

"""The measured band as a limit: which parameters the data measure, and which the model's shape extrapolates.

A fit measures K_dyn and C_eq between the lowest and the highest block frequency (and amplitude). Some
parameters are limits outside that band: seed 000's K0 is the stiffness at 0 Hz (Eq. 11 at omega = 0), K_inf the
one at infinite frequency. Their values rest on the data only as far as the band reaches towards the limit; the
rest is the model's shape carried beyond the data. With the right model that is fine; with a model missing a
branch the shape is wrong there and the limit wrong with it, by far more than its interval says (seed 000 plus
a fast Maxwell branch fitted with zener_berg on 20-50 Hz: K0 +-0.7 % but 6-8 % off, where the true structure
says K0 is not identifiable).

:func:`band_extrapolation` measures it model-agnostically on the fitted model's first harmonic (the same
function the fit matches, seed 000 Eq. 11 + the Berg element's exact first harmonic):

* the low limit K(f_lo) at f_lo = f_min / ``LIMIT_FACTOR`` (quasi-static) against K(f_min) at the band's lowest
  frequency, the high limit K(f_hi = ``LIMIT_FACTOR`` f_max) against K(f_max); the share the shape supplies is
  E = |K(limit) - K(band edge)| / |K(limit)|;
* a parameter p is a limit parameter of a side when it acts on that limit (|dK(limit) / d ln p| above ``ACTS``
  of |K(limit)|, K complex) and the band edge sees noticeably less of it (the two sensitivities differ by more than
  ``SHARE`` of the limit's): K0 acts on K(0) fully and on K(f_min) by 1 - g(f_min), g the Zener's transition
  share; a friction parameter acts alike at every frequency and is no limit;
* a limit parameter is an extrapolation (warning ``extrapolation``) when the shape's share E exceeds
  ``MIN_SHARE`` and three of the parameter's own relative standard uncertainties: its interval then states a
  precision that only the model's shape outside the band supports.

Every fit records its band (frequency and amplitude range) and, per limit parameter, the side, E and the band
(``uncertainty[p]['extrapolation']``), warned or not; K_dyn and C_eq derived from the fit hold inside that band.
"""
from __future__ import annotations

import math

import numpy as np

LIMIT_FACTOR = 1e3       # the limits are this far outside the band (a decade beyond changes nothing measurable)
ACTS = 0.05              # |d ln|K| / d ln p| at the limit above which p acts on that limit
SHARE = 0.1              # the band edge sees less of p than the limit by this share of its limit sensitivity
MIN_SHARE = 0.05         # the shape supplies at least this share of the limit value before it is warned about
UNBOUNDED_GROWTH = 2.0   # |K| growing by more than this over three decades far beyond the band: no limit there


def measured_band(blocks) -> dict:
    """{'frequency': [f_min, f_max] [Hz], 'amplitude': [a_min, a_max] [m]} of ``blocks`` (BlockResult)."""
    f = [b.frequency for b in blocks]
    a = [b.amplitude for b in blocks]
    return {'frequency': [float(min(f)), float(max(f))], 'amplitude': [float(min(a)), float(max(a))]}


def _sensitivity(spec, values: dict, name: str, f, a: float, mean: float, h: float = 1e-4):
    """DK(f) / d ln p [N/m, complex] of the model ``spec`` with ``values`` (central difference; a signed
    parameter's step is relative to |p|, or absolute at 0). The complex stiffness itself, not |K|: a friction
    parameter moves K by the same complex amount at every frequency and must not look like a limit because |K|
    and its phase change with frequency.
    """
    v = values[name]
    step = h * (abs(v) if v else 1.0)
    up = spec.with_values({**values, name: v + step}).first_harmonic(f, a, mean)
    down = spec.with_values({**values, name: v - step}).first_harmonic(f, a, mean)
    return (np.asarray(up) - np.asarray(down)) / (2 * step) * (abs(v) if v else 1.0)


def has_limit(spec, factor: float, f_edge: float, amplitude: float, mean: float) -> bool:
    """Whether the model's first-harmonic stiffness tends to a finite limit beyond the band edge ``f_edge`` [Hz]
    on the side ``factor`` points to (> 1: high frequencies, < 1: low): False when |K| still grows by more than
    ``UNBOUNDED_GROWTH`` over the three decades after ``factor^2`` x f_edge.

    A Zener (seed 000 Eq. 11) or a Maxwell branch relaxes to a value, however slowly (K - K_inf ~ (w tau)^-alpha:
    with alpha 0.3 still 15 % off at w tau = 500, so comparing two nearby frequencies would call it unbounded);
    a dashpot (K ~ j w c) or seed 003's fractional branch c (j w)^beta grows as a power of the frequency without
    end (10^(3 beta) over three decades, 58 x for beta 0.59). There is then no limit value whose share could be
    data or shape: every parameter acting there acts on the model's stiffness at every frequency beyond the band,
    which the band's K_dyn and C_eq already state; no extrapolation is recorded on that side.
    """
    f_far = f_edge * factor ** 2
    f_further = f_far * (1e3 if factor > 1 else 1e-3)
    try:
        k = np.abs(np.asarray(spec.first_harmonic(np.array([f_far, f_further]), amplitude, mean), complex).ravel())
    except (ValueError, FloatingPointError):
        return True
    if not np.all(np.isfinite(k)):
        return False
    return bool(k[1] <= UNBOUNDED_GROWTH * k[0])


def band_extrapolation(spec, values: dict, blocks, uncertainty: dict) -> dict:
    """Per free parameter of the fitted ``spec`` with ``values`` (free parameter name -> SI value) measured on
    ``blocks``: {'side': 'low'/'high', 'share': E, 'band_hz': [f_min, f_max], 'limit_hz': f, 'warn': bool} for
    limit parameters (module docstring); ``uncertainty``: name -> {'relative_sigma', ...}. Also returns the band
    under the key '_band', and under '_unbounded' the sides where the model's stiffness has no finite limit
    (:func:`has_limit`), if any.
    """
    band = measured_band(blocks)
    f_min, f_max = band['frequency']
    low_block = min(blocks, key=lambda b: b.frequency)
    high_block = max(blocks, key=lambda b: b.frequency)
    out = {'_band': band}
    sides = (('low', f_min / LIMIT_FACTOR, f_min, low_block), ('high', f_max * LIMIT_FACTOR, f_max, high_block))
    try:
        fitted = spec.with_values(values)
    except ValueError:
        return out
    for side, f_limit, f_edge, block in sides:
        a, mean = block.amplitude, block.mean
        try:
            k_limit = complex(np.asarray(fitted.first_harmonic(f_limit, a, mean)).ravel()[0])
            k_edge = complex(np.asarray(fitted.first_harmonic(f_edge, a, mean)).ravel()[0])
        except (ValueError, FloatingPointError):
            continue
        if not (math.isfinite(abs(k_limit)) and abs(k_limit) > 0):
            continue
        if not has_limit(fitted, f_limit / f_edge, f_edge, a, mean):
            out['_unbounded'] = [*out.get('_unbounded', []), side]
            continue
        share = abs(k_limit - k_edge) / abs(k_limit)
        for name in values:
            if name in out:
                continue
            try:
                s_limit = complex(np.ravel(_sensitivity(spec, values, name, f_limit, a, mean))[0])
                s_edge = complex(np.ravel(_sensitivity(spec, values, name, f_edge, a, mean))[0])
            except (ValueError, FloatingPointError):
                continue
            if abs(s_limit) <= ACTS * abs(k_limit) or abs(s_limit - s_edge) <= SHARE * abs(s_limit):
                continue
            rel = (uncertainty.get(name) or {}).get('relative_sigma', math.inf)
            out[name] = {'side': side, 'share': float(share), 'band_hz': [f_min, f_max], 'limit_hz': float(f_limit),
                         'warn': bool(share > MIN_SHARE and share > 3 * rel)}
    return out


def mark_extrapolations(fitted, values: dict, blocks, unc: dict) -> dict:
    """Record in ``unc`` (name -> result) each limit parameter's extrapolation beyond the measured band
    (fitting.extrapolation); returns the band (with 'no_limit': the sides where the model's stiffness has no finite
    limit, so no parameter there is a limit value).
    """
    found = band_extrapolation(fitted, values, blocks, unc)
    for name, x in found.items():
        if name in unc:
            unc[name]['extrapolation'] = x
    band = found['_band']
    if found.get('_unbounded'):
        band = {**band, 'no_limit': found['_unbounded']}    # sides where the model's K grows without end
    return band


def extrapolation_sentence(name: str, x: dict, unit_value: str) -> str:
    """The 'extrapolation' warning's sentence for parameter ``name``."""
    low = x['side'] == 'low'
    edge = x['band_hz'][0] if low else x['band_hz'][1]
    where = f'below {edge:.3g} Hz down to 0 Hz' if low else f'above {edge:.3g} Hz'
    return (f'{name} = {unit_value} is an extrapolation: it acts on the model\'s stiffness {where}, outside the '
            f'measured band {x["band_hz"][0]:.3g}-{x["band_hz"][1]:.3g} Hz, and {100 * x["share"]:.1f} % of the '
            f'model\'s K_dyn at the {"static" if low else "high-frequency"} limit comes from its shape there, not '
            'from data: more than the parameter\'s stated uncertainty, and a model error (a missing branch) moves '
            'it without a trace in the band; measure closer to that limit, or quote K_dyn and C_eq inside the band')
