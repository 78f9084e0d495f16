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

"""The misfit test of a fit and how it is stated: one figure, one sentence, everywhere.

:func:`misfit_test` is the two-sided chi^2 test against the measured noise (verdict's first warning; the residual
structure tests use it per harmonic and per block); :func:`misfit_sentence` states it the same way in the CLI,
the JSON (``misfit_summary``), the model file (``fit.misfit_test``, :func:`misfit_record`) and the report's header;
:func:`row_threshold` is the Sidak-corrected significance of per-block (per-row) errors.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.stats import norm

MISFIT_P = 1e-3      # p-value of each tail of the chi^2 test: the excess below which the model misfits (3.1 sigma),
#                      the deficit below which the noise was overstated
ROW_FAMILY_P = 0.0027   # two-sided 3 sigma: the family-wise false-alarm rate of the per-block (per-row) errors


def row_threshold(tests: int) -> float:
    """The |error| / sigma beyond which one of ``tests`` per-block (per-row) errors is significant: Sidak's
    correction of the two-sided 3 sigma rule, so that the family of tests together alarms at ROW_FAMILY_P.
    """
    per_test = 1.0 - (1.0 - ROW_FAMILY_P) ** (1.0 / max(int(tests), 1))
    return float(norm.isf(0.5 * per_test))


def misfit_test(chi2: float, dof: int, noise_variance_u: float = 0.0) -> dict:
    """The misfit test: is chi^2 (in units of the estimated noise variance) larger than noise explains.

    Under the model, R = chi^2/dof has mean 1 and variance 2/dof (the chi^2 distribution) plus u^2, the relative
    variance of the noise-variance estimate that chi^2 is divided by (``noise_variance_u``, relative standard
    uncertainty: noise.band_noise). z = (R - 1) / sqrt(2/dof + u^2); a misfit when its upper-tail p-value is
    below MISFIT_P. With ~5000 points and a 1 % noise estimate, R above ~1.07 misfits; with 40 points, R above
    ~1.7. Two-sided: the lower tail (``p_value_low``) below MISFIT_P is ``overstated``, a residual smaller
    than the noise allows (the noise estimate too large, or sigmas declared too large).

    Returns {chi2, dof, ratio (chi^2/dof), sd (of the ratio under the model), z, p_value (upper tail),
    p_value_low, p_value_two_sided (twice the smaller tail), noise_variance_u, misfit, overstated, test}.
    """
    dof = max(int(dof), 1)
    ratio = float(chi2) / dof
    u = float(noise_variance_u) if math.isfinite(noise_variance_u) else 1.0
    sd = math.sqrt(2.0 / dof + u ** 2)
    z = (ratio - 1.0) / sd
    p, p_low = float(norm.sf(z)), float(norm.cdf(z))
    return {'chi2': float(chi2), 'dof': dof, 'ratio': ratio, 'sd': sd, 'z': z, 'p_value': p, 'p_value_low': p_low,
            'p_value_two_sided': min(1.0, 2 * min(p, p_low)), 'noise_variance_u': u, 'misfit': p < MISFIT_P,
            'overstated': p_low < MISFIT_P, 'test': TEST_NAME}


TEST_NAME = ('two-sided chi2/dof test against the measured noise variance (normal approximation, sd = sqrt(2/dof '
             '+ u_noise^2), each tail at p < 1e-3)')


def misfit_sentence(test: dict) -> str:
    """The misfit test in one line, as the CLI, the JSON and the report state it (one figure everywhere)."""
    if not test or 'ratio' not in test:
        return 'misfit test: not made (no measured noise to judge the residual against)'
    outcome = ('misfit' if test.get('misfit') else 'noise overstated' if test.get('overstated')
               else 'consistent with noise')
    return (f'chi2/dof = {test["ratio"]:.3g} with {test["dof"]} degrees of freedom, {test["z"]:+.1f} sigma, '
            f'p = {test.get("p_value_two_sided", test["p_value"]):.2g} (two-sided): {outcome}')


def misfit_record(test: dict) -> dict:
    """The misfit test as a model file and the report keep it (plain numbers and its sentence): the same figure
    the CLI prints and its JSON states.
    """
    keep = ('ratio', 'dof', 'z', 'p_value', 'p_value_low', 'p_value_two_sided', 'misfit', 'overstated', 'test')
    out = {k: (float(test[k]) if isinstance(test[k], (float, np.floating)) else test[k])
           for k in keep if k in (test or {})}
    out['summary'] = misfit_sentence(test)
    return out
