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

"""Residual-structure tests of a time-domain fit: is what the model leaves over shaped like noise.

The overall chi^2 test (misfit.misfit_test) spreads a model error over every point. A model error is not
spread: a missing viscous branch or a wrong friction law leaves a residual *at the excitation frequency* (the
first harmonic: K_dyn and C_eq wrong) or at its odd multiples (the loop's shape wrong), in every block. These
tests concentrate on that, so they see model errors the overall chi^2 of a long record dilutes:

* harmonics: per block, the residual's least-squares projection on cos/sin of k w t (k = 1 and k = 3). Under
  the noise model each block's projection is chi^2 with 2 degrees of freedom (in units of the noise variance:
  load cell plus the displacement noise carried through the model); summed over B blocks chi^2(2B), judged
  by misfit.misfit_test with the noise estimate's own uncertainty, like the overall test;
* per block: each block's chi^2 against chi^2(n_b - 1) (its mean is removed), Bonferroni-corrected over the
  blocks, so one bad block (a disturbance, a transient) is named rather than averaged away;
* materiality: each test also needs its effect above a floor (HARMONIC_FLOOR, WHITENESS_FLOOR), what the fit's
  idealisation of the input leaves with the true model; below it a structure is reported, not warned about;
* whiteness: the residual's lag-1 autocorrelation between neighbouring analysed points of a block, against
  what a correct model leaves: the load cell's noise is white, but the displacement noise reaches the force
  through the model input's zero-phase low-pass (timefit.model_input), so its share of the residual
  correlates (TimeProblem.input_noise measures that correlation); z = (rho - rho_0) sqrt(N), two-sided.
  A model error leaves a smooth residual: 0.3 for a missing Maxwell branch, 0.9 for a missing cubic spring
  (seed 000's grid), against +-0.014 of noise.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.stats import norm

from .misfit import MISFIT_P, misfit_test

HARMONICS = (1, 3)
# Materiality: a structure is a misfit when it is beyond noise (MISFIT_P) AND larger than what the fit's own
# idealisation of a correct model leaves. Measured on the true model (seed 000 at 20 and -40 degC, 3-cycle
# blocks of 0.5-14 Hz, 10 N load-cell noise): a residual at the excitation frequency of 0.026-0.036 % of the
# block's force amplitude (4.4 sigma there) and a lag-1 autocorrelation 0.06-0.09 above the noise's; with 20 N
# noise on seed 000's grid the noise alone reaches 0.05 % in the worst block. A missing Maxwell branch
# (2 kN/mm, 5 kN s/m) leaves 0.27 % and +0.31; a missing cubic spring 1.4 % (0.9 % at 3 w) and +0.90.
HARMONIC_FLOOR = 1e-3      # residual harmonic amplitude / block force amplitude
WHITENESS_FLOOR = 0.15     # lag-1 autocorrelation above the noise's


def _projection(r, t, omega) -> float:
    """||P r||^2: the squared norm of r's least-squares fit by cos and sin of omega t (r: unit-variance noise)."""
    a = np.column_stack([np.cos(omega * t), np.sin(omega * t)])
    coef, *_ = np.linalg.lstsq(a, r, rcond=None)
    fit = a @ coef
    return float(fit @ fit)


def residual_structure(problem, r, shares, noise_variance_u: float, lag1_expected=None, n_free: int = 0) -> dict:
    """The residual-structure tests of a time-domain fit (module docstring).

    problem: the TimeProblem; r: its residual vector at the optimum (units of the load-cell noise);
    shares: per item (recording), sigma_F^2 / (sigma_F^2 + sigma_in^2), the load cell's part of the noise
    variance (time_misfit), so r^2 * share is in units of the whole noise variance; noise_variance_u: relative
    standard uncertainty of the noise-variance estimate; lag1_expected: per item, the lag-1 autocorrelation a
    correct model's residual has (default 0: white); n_free: the fit's free parameters, which act on the first
    harmonic and take that many degrees of freedom from its test.

    Returns {'harmonic_<k>': misfit_test result with 'worst' (the block whose residual at k w is largest
    relative to its force amplitude: frequency [Hz], amplitude [noise sigmas], relative [-]) and 'misfit' only
    when that relative amplitude is also above HARMONIC_FLOOR, 'blocks': [{'frequency', 'chi2_per_dof',
    'p_value'}] of blocks beyond MISFIT_P / B,
    'n_blocks', 'whiteness': {'lag1', 'expected', 'z', 'p_value', 'misfit'}}.
    """
    rows_of_item = []
    for k, rows in enumerate(problem.item_rows):
        rows_of_item += [k] * sum(1 for b in problem.block_rows if rows.start <= b.start < rows.stop)
    windows = [idx for item in problem.items for idx in item[4]]
    sums = {k: [0.0, 0] for k in HARMONICS}
    worst = {k: (0.0, 0.0, 0.0) for k in HARMONICS}    # (frequency, amplitude [sigmas], relative amplitude)
    bad, lag_num, lag_den, lag_0, n_lag = [], 0.0, 0.0, 0.0, 0
    periodic = [i for i, f in enumerate(problem.block_frequency) if f]
    for i, (rows, f, idx, item) in enumerate(zip(problem.block_rows, problem.block_frequency, windows,
                                                 rows_of_item, strict=True)):
        part = r[rows] * math.sqrt(shares[item])
        if part.size < 8:
            continue
        lag_num += float(part[1:] @ part[:-1])
        lag_den += float(part @ part)
        # removing each block's mean makes white noise's lag-1 estimate -1/n on average
        lag_0 += ((lag1_expected[item] if lag1_expected else 0.0) - 1.0 / part.size) * (part.size - 1)
        n_lag += part.size - 1
        if not f:
            continue
        run, _, _, force, _, sigma = problem.items[item]
        t = idx * run.dt
        force_amplitude = max(0.5 * float(np.ptp(force[idx])), 1e-300)
        for k in HARMONICS:
            if k * f < 0.45 / (run.dt * max(1, idx[1] - idx[0])):   # below the points' Nyquist
                s = _projection(part, t, 2 * math.pi * k * f)
                sums[k][0] += s
                sums[k][1] += 2
                amp = math.sqrt(2 * s / part.size)          # amplitude of that harmonic [noise sigmas]
                relative = amp * sigma / math.sqrt(shares[item]) / force_amplitude
                if relative > worst[k][2]:
                    worst[k] = (f, amp, relative)
        test = misfit_test(float(part @ part), part.size - 1, noise_variance_u)
        if test['p_value'] < MISFIT_P / max(len(periodic), 1):
            bad.append({'frequency': f, 'chi2_per_dof': test['ratio'], 'p_value': test['p_value'], 'index': i})
    out = {'n_blocks': len(periodic), 'blocks': bad}
    for k in HARMONICS:
        chi2, dof = sums[k]
        dof -= n_free if k == 1 else 0
        if dof > 0:
            test = misfit_test(chi2, dof, noise_variance_u)
            test['worst'] = {'frequency': worst[k][0], 'amplitude_sigmas': worst[k][1], 'relative': worst[k][2]}
            test['beyond_noise'] = test['misfit']
            test['misfit'] = test['misfit'] and worst[k][2] > HARMONIC_FLOOR
            out[f'harmonic_{k}'] = test
    if lag_den > 0 and n_lag:
        rho, rho_0 = lag_num / lag_den, lag_0 / n_lag
        z = (rho - rho_0) * math.sqrt(n_lag)
        p = float(2 * norm.sf(abs(z)))
        out['whiteness'] = {'lag1': rho, 'expected': rho_0, 'z': z, 'p_value': p, 'beyond_noise': p < MISFIT_P,
                            'misfit': p < MISFIT_P and rho - rho_0 > WHITENESS_FLOOR}
    return out
