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

"""The verdict of a fit: a warning for everything that makes the numbers less than they look.

Each warning is one sentence a test engineer can act on. A clean fit has none. Thresholds:

* misfit: chi^2 / dof above ``MISFIT_CHI2`` (the residual is larger than the load-cell noise the
  recording shows: the model misses something the data contain);
* per-block errors of the fitted model run over the measured displacement above the README's targets,
  ``TARGET_K`` for K_dyn and ``TARGET_C`` for C_eq, and above 3 sigma of the block's measurement (a
  small loss measured with a noisy load cell is not a target miss);
* a systematic pattern: the per-block K_dyn or C_eq errors follow frequency or amplitude (a linear
  trend in ln f or A whose change over the measured range exceeds ``PATTERN_K`` / ``PATTERN_C`` and
  four of its standard errors);
* unidentifiable parameters: a relative sigma above ``MAX_RELATIVE_SIGMA``; two parameters correlated
  above ``MAX_CORRELATION`` when that leaves either of them worse than ``CORRELATED_SIGMA`` by the
  noise-based sigma (the information in the data, where the correlation comes from; a correlation
  alone is not a defect: seed 000's x2 and F_fmax correlate at +0.99 on its own test grid and are still
  identified to about 1 %; such pairs are listed in the notes); a signed term whose 95 % interval holds
  0; a parameter at its search bound;
* a load-cell delay estimated more than 4 sigma from zero.
"""
from __future__ import annotations

import math

import numpy as np

from .modelfit import DELAY

MISFIT_CHI2 = 1.5
TARGET_K, TARGET_C = 0.01, 0.05
PATTERN_K, PATTERN_C = 0.005, 0.025
MAX_CORRELATION = 0.95
MAX_RELATIVE_SIGMA = 0.3
CORRELATED_SIGMA = 0.1


def _pct(v):
    return f'{100 * v:.2g} %' if abs(v) < 0.1 else f'{100 * v:.0f} %'


def _trend(errors, x):
    """(change of the fitted linear trend over the range of x, its standard error)."""
    if np.ptp(x) <= 0 or errors.size < 4:
        return 0.0, math.inf
    a = np.column_stack([np.ones_like(x), x - x.mean()])
    coef, res, *_ = np.linalg.lstsq(a, errors, rcond=None)
    dof = errors.size - 2
    s2 = float(np.sum((errors - a @ coef) ** 2)) / max(dof, 1)
    se = math.sqrt(s2 / max(float(np.sum((x - x.mean()) ** 2)), 1e-300))
    span = float(np.ptp(x))
    return coef[1] * span, se * span


def misfit_warnings(fit) -> list:
    out = []
    if fit.chi2_per_dof > MISFIT_CHI2:
        if fit.method == 'harmonic' and fit.runs and fit.noise:
            # the blocks' K_dyn and C_eq against the exact first harmonics of ideal sines: the actuator's
            # distortion and the rig's time scheme differ from those by more than a low noise resolves
            out.append(f'misfit beyond noise: chi2/dof = {fit.chi2_per_dof:.3g} of the blocks\' K_dyn and C_eq '
                       'against the first harmonics of ideal sines: the model or the idealisation (the measured '
                       'motion is not a pure sine) does not describe the data to the noise; the uncertainties '
                       'are inflated by this misfit; --method time runs the model over the measured motion')
        else:
            sigma = np.mean(list(fit.noise.values())) if fit.noise else math.nan
            out.append(f'misfit beyond noise: chi2/dof = {fit.chi2_per_dof:.3g} (the force residual is '
                       f'{math.sqrt(fit.chi2_per_dof):.2g} x the load-cell noise of {sigma:.3g} N): the model '
                       'does not describe what the data show; the uncertainties are inflated by this misfit')
    kind = 'simulated' if any('simulated' in q for q in fit.quality) else 'analytic'
    rows = [q for q in fit.quality if kind in q]
    if not rows:
        return out
    ek = np.array([q[kind]['e_k'] for q in rows])
    ec = np.array([q[kind]['e_c'] for q in rows])
    sk = np.array([q['measured'].get('rel_sigma_k', 0.0) for q in rows])
    sc = np.array([q['measured'].get('rel_sigma_c', 0.0) for q in rows])
    for name, e, target, s in (('K_dyn', ek, TARGET_K, sk), ('C_eq', ec, TARGET_C, sc)):
        bad = np.flatnonzero((np.abs(e) > target) & (np.abs(e) > 3 * s))
        if bad.size:
            w = bad[np.argmax(np.abs(e[bad]))]
            q = rows[w]
            out.append(f'{name} error above the {_pct(target)} target in {bad.size} of {len(rows)} blocks '
                       f'(worst {100 * e[w]:+.2f} % at {q["frequency"]:.3g} Hz, {1e3 * q["amplitude"]:.3g} mm)')
    lf = np.log([q['frequency'] for q in rows])
    amp = np.array([q['amplitude'] for q in rows])
    for name, e, limit in (('K_dyn', ek, PATTERN_K), ('C_eq', ec, PATTERN_C)):
        for what, x in (('frequency', lf), ('amplitude', amp)):
            change, se = _trend(e, x)
            if abs(change) > limit and abs(change) > 4 * se:
                out.append(f'systematic {name} residual with {what}: the model error changes by '
                           f'{100 * change:+.2f} % over the measured {what} range (a model error, not noise)')
    return out


def identifiability_warnings(fit, coords) -> list:
    out = []
    names = list(fit.uncertainty)
    corr = np.asarray(fit.correlation)
    for i, j in correlated_pairs(fit):
        # what the data can tell apart is a property of their information (the noise covariance, which the
        # correlation comes from too); the block jackknife's scatter has its own warning above 30 %
        worst = max(_relative_noise_sigma(fit.uncertainty[names[i]]), _relative_noise_sigma(fit.uncertainty[names[j]]))
        if worst > CORRELATED_SIGMA:
            out.append(f'{names[i]} and {names[j]} cannot be told apart by these data (correlation '
                       f'{corr[i, j]:+.3f}, +-{100 * worst:.0f} % at 1 sigma): only a combination of them is '
                       'identified; widen the frequency/amplitude range or fix one')
    for k, u in fit.uncertainty.items():
        if k == DELAY:
            continue
        kind = coords.kinds[coords.names.index(k)] if k in coords.names else 'log'
        lo, hi = u['interval_95']
        if kind == 'lin' and lo <= 0 <= hi:
            out.append(f'{k} is consistent with zero ({u["value"]:.3g} +- {u["sigma"]:.2g}): the data do not '
                       'need this term')
        elif kind != 'lin' and u['relative_sigma'] > MAX_RELATIVE_SIGMA:
            out.append(f'{k} is poorly determined (+-{100 * u["relative_sigma"]:.0f} % at 1 sigma): the data '
                       f'do not constrain it')
    for k in fit.bounds_hit:
        out.append(f'{k} ended at the edge of its search range: the optimum may lie beyond it, '
                   'or the model structure does not suit the data')
    if fit.refinement_limited:
        out.append(f'the time-domain fit stopped at the edge of its range around the first-harmonic estimate '
                   f'({", ".join(fit.refinement_limited)}): the loops and the first harmonics disagree, a sign of '
                   'a model or data problem')
    return out


def _relative_noise_sigma(u) -> float:
    return u.get('sigma_noise', u['sigma']) / abs(u['value']) if u['value'] else math.inf


def correlated_pairs(fit) -> list:
    """Index pairs (i, j) of parameters correlated above MAX_CORRELATION."""
    corr = np.asarray(fit.correlation)
    n = corr.shape[0] if corr.ndim == 2 else 0
    return [(i, j) for i in range(n) for j in range(i + 1, n) if abs(corr[i, j]) > MAX_CORRELATION]


def notes(fit) -> list:
    """What a reader should know that is not a defect: strongly correlated pairs and their sigmas."""
    names = list(fit.uncertainty)
    corr = np.asarray(fit.correlation)
    return [f'{names[i]} and {names[j]} are correlated ({corr[i, j]:+.3f}); each is still determined to '
            f'+-{100 * fit.uncertainty[names[i]]["relative_sigma"]:.2g} % and '
            f'+-{100 * fit.uncertainty[names[j]]["relative_sigma"]:.2g} % (1 sigma, marginal)'
            for i, j in correlated_pairs(fit)]


def delay_warnings(fit) -> list:
    d = fit.load_cell.get('delay_estimated')
    s = fit.load_cell.get('delay_sigma')
    if d is None or s is None or not (abs(d) > 4 * s):
        return []
    return [f'load-cell delay estimated at {1e3 * d:+.3f} +- {1e3 * s:.3f} ms beyond the calibration applied '
            f'({1e3 * fit.load_cell.get("delay", 0.0):.3f} ms): the parameters are corrected for it; check the '
            'sensor timing and give --load-cell-delay once it is known']


def verdict(fit, coords) -> list:
    """All warnings of ``fit`` (a ModelFit) in the order: misfit, identifiability, load cell."""
    return misfit_warnings(fit) + identifiability_warnings(fit, coords) + delay_warnings(fit)
