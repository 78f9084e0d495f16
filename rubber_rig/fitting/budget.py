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

"""The uncertainty budget of each identified parameter, in the manner of the GUM (JCGM 100:2008).

Contributions (standard uncertainties, in the parameter's unit):

* ``type_a``: statistical, from the data (the larger of the noise-based and the block-jackknife sigma,
  modelfit.physical_uncertainty);
* ``load_cell_gain`` (Type B): the declared standard uncertainty u_g of the load cell's gain g. Every force
  the model produces scales with its force-scaled parameters (stiffnesses, dampings, friction forces,
  fractional coefficients: FORCE_SCALES), so a gain error g(1 + e) scales each of them by 1/(1 + e) and leaves
  the others (times, lengths, orders) alone: u = |value| u_g / g. Sensitivity coefficient exact to first order.
* ``load_cell_delay`` (Type B): the declared standard uncertainty u_d of the load-cell delay, carried through
  the fit: the parameters' shift for a delay change of u_d, linearised at the optimum (Gauss-Newton:
  dz = -(J^T J)^-1 J^T dr/dd u_d).
* ``displacement_gain`` (Type B): the declared standard uncertainty u_x of the displacement transducer's gain.
  A displacement read (1 + e) x too large makes every parameter whose unit holds length to the power L come
  out (1 + e)^L x too large (a stiffness N/m: L = -1, k3 in N/m^3: -3, Berg's x2 in m: +1; times, orders and
  forces: 0), so u = |L| |value| u_x (:func:`length_exponent`).

* ``displacement_noise`` (Type B): the bias the displacement transducer's noise leaves in Berg's x2 and F_fmax
  through the model's input (errors in variables: the element turns at the noisy extremes), as measured and scaled
  in fitting.inputnoise (x2 and F_fmax +1.0 % and +1.14 % per 0.2 um of noise, the larger of two specimens
  measured); estimated, not corrected, so its full size is the standard uncertainty.

The total is the root sum of squares (contributions uncorrelated). A contribution that was not declared is
None, and the fit's warnings say so (code ``calibration_undeclared``) with what a typical class would add.

The 95 % interval is computed from the total in a parameterisation that respects the parameter's physical
bounds (``interval_method``): ``log`` for positive parameters (value x exp(+-k u/value)), ``logit`` for a
fractional order inside (0, 1), ``clipped`` (linear, cut to [0, 1]) for an order at its bound 1 (a legitimate
value: a plain dashpot), ``linear`` for signed terms and the delay; k is the coverage factor the fit used for
its Type A interval (Student's t over the blocks).

An interval is honest at its edges: where the linearised uncertainty says nothing (a positive parameter whose
k u exceeds ``UNBOUNDED_LOG`` in the log, i.e. an upper end beyond ``exp(UNBOUNDED_LOG)`` times the value), the
side is reported as unbounded: ``inf`` above and the physical bound 0 below, and ``interval_note`` says why;
never an overflowed number (the 2e-298 .. null of a bushing fitted on 0.2-2 Hz). A sigma that could not be
computed at all gives [-inf, inf] (or [0, inf]) with its reason. JSON writes inf as the string "inf".
"""
from __future__ import annotations

import math

import numpy as np

FORCE_SCALES = ('stiffness', 'force', 'damping', 'k2', 'k3', 'k5', 'frac_alpha', 'frac_beta')
CLASS_05_GAIN_U = 0.005 / math.sqrt(3.0)   # a class 0.5 load cell: +-0.5 % of reading, rectangular
UNBOUNDED_LOG = math.log(100.0)   # a log interval reaching past 100 x the value is no bound (linearisation fails)


def _expit(z: float) -> float:
    return 1 / (1 + math.exp(-z)) if z >= 0 else math.exp(z) / (1 + math.exp(z))


def interval(value: float, sigma: float, k: float, method: str) -> list:
    """[lo, hi]: value -+ k sigma in the parameterisation ``method`` (log, logit, clipped or linear); a side the
    data do not bound is inf (above) or the physical bound 0 (below a positive parameter): :func:`interval_note`.
    """
    if not (math.isfinite(sigma) and math.isfinite(value)):
        return [0.0 if method == 'log' else -math.inf, math.inf]
    if method == 'log' and value > 0:
        s = k * sigma / value
        if s > UNBOUNDED_LOG:
            return [0.0, math.inf]
        return [value * math.exp(-s), value * math.exp(s)]
    if method == 'logit' and 0 < value < 1:
        s = k * sigma / (value * (1 - value))
        z = math.log(value / (1 - value))
        return [_expit(z - s), _expit(z + s)]
    if method == 'clipped':            # an order at its bound 1 (or 0): the linear interval within [0, 1]
        return [max(0.0, value - k * sigma), min(1.0, value + k * sigma)]
    return [value - k * sigma, value + k * sigma]


def interval_note(value: float, sigma: float, k: float, method: str) -> str | None:
    """Why an interval (:func:`interval`) has an unbounded side, or None when both sides are bounds."""
    if not (math.isfinite(sigma) and math.isfinite(value)):
        return 'unbounded: no uncertainty could be computed for this parameter (the data carry no information on it)'
    if method == 'log' and value > 0 and k * sigma / value > UNBOUNDED_LOG:
        return (f'unbounded: k sigma is {k * sigma / value:.3g} x the value, so the data bound it neither above (inf) '
                'nor below its physical bound 0; the parameter is not identified by these data')
    return None


def interval_method(kind: str, value: float) -> str:
    """How a parameter of coordinate ``kind`` (modelfit.Coordinates) gets its interval."""
    if kind == 'order':
        return 'logit' if 1e-6 < value < 1 - 1e-6 else 'clipped'
    if kind in ('log', 'above'):
        return 'log'
    return 'linear'


def length_exponent(unit: str) -> int:
    """The power of metres in a unit written as catalogue.ParamSpec does: 'N/m' -> -1, 'N/m^3' -> -3, 'm' -> 1,
    'N s^alpha/m' -> -1, 's/m' -> -1, 's' or '-' -> 0.
    """
    num, _, den = str(unit).partition('/')
    power = 0
    for sign, part in ((1, num), (-1, den)):
        for token in part.split():
            base, _, exp = token.partition('^')
            if base == 'm':
                power += sign * (int(exp) if exp.lstrip('-').isdigit() else 1)
    return power


def add_budget(unc: dict, kinds: dict, scales: dict, calibration: dict, delay_shift: dict | None = None,
               delay_estimated: bool = False, units: dict | None = None, input_noise: dict | None = None) -> None:
    """Extend ``unc`` (name -> {value, sigma, interval_95, ...}) in place with each parameter's budget.

    ``kinds``: name -> coordinate kind; ``scales``: name -> scale kind of the model's parameter (FORCE_SCALES);
    ``calibration``: {'gain', 'gain_u', 'delay_u', 'displacement_gain_u'} (None: not declared); ``delay_shift``:
    name -> the parameter's change for a 1 s change of the declared delay (None when the delay was estimated by
    the fit: its uncertainty is then part of Type A); ``units``: name -> the parameter's unit (for the
    displacement gain's contribution; None: no such contribution); ``input_noise``: name -> the standard
    uncertainty of the bias the displacement noise leaves in it (fitting.inputnoise: ``displacement_noise``).
    """
    gain, gain_u, delay_u = calibration.get('gain', 1.0), calibration.get('gain_u'), calibration.get('delay_u')
    x_u = calibration.get('displacement_gain_u')
    for name, u in unc.items():
        value, a = u['value'], u['sigma']
        k = (u['interval_95'][1] - u['interval_95'][0]) / (2 * a) if a > 0 else 1.96
        contributions = {'type_a': a}
        if scales.get(name) in FORCE_SCALES:
            contributions['load_cell_gain'] = None if gain_u is None else abs(value) * gain_u / gain
        if delay_shift is not None and name in delay_shift and not delay_estimated:
            contributions['load_cell_delay'] = None if delay_u is None else abs(delay_shift[name]) * delay_u
        power = length_exponent(units[name]) if units and name in units else 0
        if power:
            contributions['displacement_gain'] = None if x_u is None else abs(power * value) * x_u
        if input_noise and name in input_noise:
            contributions['displacement_noise'] = float(input_noise[name])
        total = math.sqrt(sum(c ** 2 for c in contributions.values() if c is not None))
        method = interval_method(kinds.get(name, 'lin'), value)
        u.update({'budget': contributions, 'sigma_type_a': a, 'sigma': total,
                  'relative_sigma': total / abs(value) if value else math.inf,
                  'interval_95': [float(v) for v in interval(value, total, k, method)],
                  'interval_method': method, 'coverage_factor': k})
        note = interval_note(value, total, k, method)
        if note:
            u['interval_note'] = note
        else:
            u.pop('interval_note', None)


def linearised_shift(coords, z, jac, jd) -> tuple:
    """(shift, dz): each parameter's change [its unit per unit of the perturbation] when the residuals change
    by ``jd`` per unit of a perturbation (a delay, say), the other parameters refitted: one Gauss-Newton step at
    the optimum ``z`` of search coordinates ``coords`` with Jacobian ``jac`` (dz = -(J^T J)^-1 J^T jd), mapped
    to the physical parameters by central differences along dz.
    """
    bread = np.linalg.pinv(jac.T @ jac)
    dz = -bread @ (jac.T @ jd)
    eps = 1e-6
    up, down = coords.values(z + dz * eps), coords.values(z - dz * eps)
    return {n: (float(up[n]) - float(down[n])) / (2 * eps) for n in coords.names}, dz


def undeclared(unc: dict) -> list:
    """Names of the budget contributions that apply to some parameter but were not declared."""
    out = []
    for u in unc.values():
        for key, c in (u.get('budget') or {}).items():
            if c is None and key not in out:
                out.append(key)
    return out
