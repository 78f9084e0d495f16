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

* misfit: a statistical test (:func:`misfit.misfit_test`), not a fixed chi^2/dof: the residual variance against the
  noise variance the recording shows (load cell, plus the displacement transducer's noise carried through the
  model, errors in variables), with the chi^2 distribution's spread for these degrees of freedom and the
  uncertainty of the noise estimate itself; a misfit when the excess has a p-value below ``MISFIT_P``; the
  test is two-sided: chi^2 too *small* (lower-tail p-value below ``MISFIT_P``) means the noise the residual is
  measured against was overstated (or the model fitted the noise), its own warning ``noise_overstated``;
* per-block errors of the fitted model run over the measured displacement above the README's targets,
  ``TARGET_K`` for K_dyn and ``TARGET_C`` for C_eq, and beyond the block's measurement sigma by
  :func:`row_threshold` (a small loss measured with a noisy load cell is not a target miss): 3 sigma for one
  test, Sidak-corrected for the 2 B tests of B blocks (table rows), so a correct model's chance of any row
  warning stays 0.27 % however long the table (3.9 sigma per test for 15 rows);
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

from .budget import CLASS_05_GAIN_U, undeclared
from .diagnoses import drift_sentence, outlier_sentence, saturation_sentence
from .extrapolation import extrapolation_sentence
from .fitwarnings import FitWarning
from .misfit import misfit_test, row_threshold
from .modelfit import DELAY, paper_unit
from .temperature import temperature_sentences

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
    test = fit.misfit or (misfit_test(fit.chi2, fit.dof) if math.isfinite(fit.chi2) else {'misfit': False})
    if test['misfit']:
        why = (f'chi2/dof = {test["ratio"]:.3g} with {test["dof"]} degrees of freedom is {test["z"]:.1f} sigma '
               f'beyond noise (p = {test["p_value"]:.1g}; sigma of chi2/dof {test["sd"]:.2g}, the noise '
               f'estimate\'s own uncertainty included)')
        if fit.method == 'harmonic' and fit.runs and fit.noise:
            # the blocks' K_dyn and C_eq against the exact first harmonics of ideal sines: the actuator's
            # distortion and the rig's time scheme differ from those by more than a low noise resolves
            out.append(FitWarning(
                'misfit', f'misfit beyond noise: {why}, of the blocks\' K_dyn and C_eq against the first harmonics '
                'of ideal sines: the model or the idealisation (the measured motion is not a pure sine) does not '
                'describe the data to the noise; the uncertainties are inflated by this misfit; --method time runs '
                'the model over the measured motion'))
        else:
            sigma = np.mean(list(fit.noise.values())) if fit.noise else math.nan
            inputs = test.get('input_noise') or {}
            carried = (f', plus {np.mean(list(inputs.values())):.3g} N carried from the displacement noise through '
                       'the model') if inputs and max(inputs.values()) > 0 else ''
            out.append(FitWarning(
                'misfit', f'misfit beyond noise: {why}; the force residual is {math.sqrt(test["ratio"]):.2g} x the '
                f'noise (load cell {sigma:.3g} N{carried}): the model does not describe what the data show, and no '
                'sensor delay, gain or offset may be read from this fit; the uncertainties are inflated by this '
                'misfit'))
    if test.get('overstated'):
        out.append(FitWarning(
            'noise_overstated', f'the residual is smaller than the noise allows: chi2/dof = {test["ratio"]:.3g} with '
            f'{test["dof"]} degrees of freedom is {-test["z"]:.1f} sigma below 1 (p = {test["p_value_low"]:.1g}): '
            'the noise the fit is judged against was overstated (a noise estimate eaten by the signal, or declared '
            'sigmas too large), so the misfit test is blind by that much and the noise-based uncertainties are '
            'too wide; check the load-cell noise figure'))
    out += structure_warnings((fit.misfit or {}).get('structure'))
    kind = 'simulated' if any('simulated' in q for q in fit.quality) else 'analytic'
    rows = [q for q in fit.quality if kind in q]
    if not rows:
        return out
    ek = np.array([q[kind]['e_k'] for q in rows])
    ec = np.array([q[kind]['e_c'] for q in rows])
    sk = np.array([q['measured'].get('rel_sigma_k', 0.0) for q in rows])
    sc = np.array([q['measured'].get('rel_sigma_c', 0.0) for q in rows])
    z_row = row_threshold(2 * len(rows))
    for name, e, target, s in (('K_dyn', ek, TARGET_K, sk), ('C_eq', ec, TARGET_C, sc)):
        bad = np.flatnonzero((np.abs(e) > target) & (np.abs(e) > z_row * s))
        if bad.size:
            w = bad[np.argmax(np.abs(e[bad]))]
            q = rows[w]
            out.append(FitWarning('misfit', f'{name} error above the {_pct(target)} target in {bad.size} of '
                                  f'{len(rows)} blocks (worst {100 * e[w]:+.2f} % at {q["frequency"]:.3g} Hz, '
                                  f'{1e3 * q["amplitude"]:.3g} mm), beyond {z_row:.2g} sigma of the measurement '
                                  f'(3 sigma Sidak-corrected for {2 * len(rows)} tests)'))
    lf = np.log([q['frequency'] for q in rows])
    amp = np.array([q['amplitude'] for q in rows])
    for name, e, limit in (('K_dyn', ek, PATTERN_K), ('C_eq', ec, PATTERN_C)):
        for what, x in (('frequency', lf), ('amplitude', amp)):
            change, se = _trend(e, x)
            if abs(change) > limit and abs(change) > 4 * se:
                out.append(FitWarning('misfit', f'systematic {name} residual with {what}: the model error changes '
                                      f'by {100 * change:+.2f} % over the measured {what} range (a model error, '
                                      'not noise)'))
    return out


def structure_warnings(structure) -> list:
    """One 'misfit' warning naming each residual-structure test (structure.residual_structure) that fails."""
    if not structure:
        return []
    found, names = [], []
    for k, what in ((1, 'K_dyn and C_eq'), (3, 'the loop\'s shape (friction, a nonlinear spring)')):
        test = structure.get(f'harmonic_{k}')
        if test and test['misfit']:
            w = test['worst']
            times = 'the excitation frequency' if k == 1 else f'{k} x the excitation frequency'
            found.append(f'a residual at {times} {test["z"]:.0f} sigma beyond noise over {structure["n_blocks"]} '
                         'blocks '
                         f'(up to {100 * w["relative"]:.2g} % of the force amplitude, {w["amplitude_sigmas"]:.2g} '
                         f'noise sigmas, at {w["frequency"]:.3g} Hz): {what} not '
                         'described to the noise')
            names.append(f'harmonic_{k}')
    if structure.get('blocks'):
        worst = max(structure['blocks'], key=lambda b: b['chi2_per_dof'])
        found.append(f'{len(structure["blocks"])} of {structure["n_blocks"]} blocks misfit on their own (worst '
                     f'chi2/dof {worst["chi2_per_dof"]:.2f} at {worst["frequency"]:.3g} Hz)')
        names.append('blocks')
    white = structure.get('whiteness')
    if white and white['misfit']:
        found.append(f'the residual is not white (lag-1 autocorrelation {white["lag1"]:+.2f} where the noise gives '
                     f'{white["expected"]:+.2f}, z = {white["z"]:.0f}): it is smooth, systematic')
        names.append('whiteness')
    if not found:
        return []
    return [FitWarning('misfit', 'residual structure beyond noise: ' + '; '.join(found) + '; a model error, which no '
                       'sensor delay, gain or offset may be read from', tuple(names))]


def identifiability_warnings(fit, coords) -> list:
    out = []
    names = list(fit.uncertainty)
    corr = np.asarray(fit.correlation)
    for i, j in correlated_pairs(fit):
        # what the data can tell apart is a property of their information (the noise covariance, which the
        # correlation comes from too); the block jackknife's scatter has its own warning above 30 %
        worst = max(_relative_noise_sigma(fit.uncertainty[names[i]]), _relative_noise_sigma(fit.uncertainty[names[j]]))
        if worst > CORRELATED_SIGMA:
            out.append(FitWarning('identifiability', f'{names[i]} and {names[j]} cannot be told apart by these '
                                  f'data (correlation {corr[i, j]:+.3f}, +-{100 * worst:.0f} % at 1 sigma): only a '
                                  'combination of them is identified; widen the frequency/amplitude range or fix one',
                                  (names[i], names[j])))
    for k, u in fit.uncertainty.items():
        if k == DELAY:
            continue
        kind = coords.kinds[coords.names.index(k)] if k in coords.names else 'log'
        lo, hi = u['interval_95']
        if kind == 'lin' and lo <= 0 <= hi:
            out.append(FitWarning('identifiability', f'{k} is consistent with zero ({u["value"]:.3g} +- '
                                  f'{u["sigma"]:.2g}): the data do not need this term', (k,)))
        elif kind != 'lin' and u['relative_sigma'] > MAX_RELATIVE_SIGMA:
            out.append(FitWarning('identifiability', f'{k} is poorly determined (+-{100 * u["relative_sigma"]:.0f} % '
                                  'at 1 sigma): the data do not constrain it', (k,)))
    for k in fit.bounds_hit:
        if k == DELAY and fit.parameters.get(DELAY, 0.0) + fit.load_cell.get('delay', 0.0) < 1e-5:
            out.append(FitWarning('delay', 'the fit asks for a negative load-cell delay (the force measured before '
                                  'it acts), which is never applied: the model lags the specimen, a model error '
                                  '(e.g. a missing viscous branch), not a sensor; the delay was held at zero', (k,)))
            continue
        out.append(FitWarning('bounds', f'{k} ended at the edge of its search range: the optimum may lie beyond '
                              'it, or the model structure does not suit the data', (k,)))
    if fit.refinement_limited:
        out.append(FitWarning('misfit', 'the time-domain fit stopped at the edge of its range around the '
                              f'first-harmonic estimate ({", ".join(fit.refinement_limited)}): the loops and the first '
                              'harmonics disagree, a sign of a model or data problem', fit.refinement_limited))
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
    return [FitWarning('delay', f'load-cell delay estimated at {1e3 * d:+.3f} +- {1e3 * s:.3f} ms beyond the '
                       f'calibration applied ({1e3 * fit.load_cell.get("delay", 0.0):.3f} ms): the parameters are '
                       'corrected for it; check the sensor timing and give --load-cell-delay once it is known',
                       (DELAY,))]


def calibration_warnings(fit, misfits: bool) -> list:
    """Declared calibrations: what is missing from the budget, and a delay the data prefer beyond the declared one
    (a diagnostic, never applied; when the model misfits it says nothing about the sensor).
    """
    out = []
    missing = undeclared(fit.uncertainty)
    if 'load_cell_gain' in missing:
        scaled = [n for n, u in fit.uncertainty.items() if (u.get('budget') or {}).get('load_cell_gain', 0) is None]
        out.append(FitWarning('calibration_undeclared', 'the load-cell gain uncertainty is not declared (rig '
                              'configuration load_cell_gain_u, or --load-cell-gain-u): the force-scaled parameters '
                              f'({", ".join(scaled)}) carry no calibration contribution; a class 0.5 load cell would '
                              f'add {100 * CLASS_05_GAIN_U:.2f} % (1 sigma) to each', scaled))
    if 'load_cell_delay' in missing:
        out.append(FitWarning('calibration_undeclared', 'the load-cell delay uncertainty is not declared (rig '
                              'configuration load_cell_delay_u, or --load-cell-delay-u): its effect on the loss '
                              'parameters is missing from the budget (a delay known to +-20 us costs seed 000\'s '
                              'tau about 7 %, README "Declaring the load cell")', ()))
    if 'displacement_gain' in missing:
        scaled = [n for n, u in fit.uncertainty.items()
                  if 'displacement_gain' in (u.get('budget') or {}) and u['budget']['displacement_gain'] is None]
        out.append(FitWarning('calibration_undeclared', 'the displacement transducer\'s gain uncertainty is not '
                              'declared (rig configuration displacement_gain_u, or --displacement-gain-u): the '
                              f'parameters with a length in their unit ({", ".join(scaled)}) carry no calibration '
                              f'contribution; a transducer calibrated to +-0.5 % of reading would add '
                              f'{100 * CLASS_05_GAIN_U:.2f} % per power of length (k3 in N/m^3: 3 x that)', scaled))
    if fit.temperature is not None and (fit.load_cell or {}).get('temperature_u', 0.0) is None:
        out.append(FitWarning('calibration_undeclared', f'the temperature sensor\'s uncertainty is not declared (rig '
                              'configuration temperature_u, or --temperature-u): the parameters belong to '
                              f'{fit.temperature:g} degC +- an unknown amount; rubber\'s loss parameters move by '
                              'about 1.5 %/K (seed 000 Table 1: tau -28 %, alpha +21 % from 20 to 0 degC)', ()))
    check = fit.load_cell.get('delay_check')
    if check:
        u_d = fit.load_cell.get('delay_u') or 0.0
        est, s = check['estimate'], check['sigma']
        declared = fit.load_cell.get('delay', 0.0)
        if abs(est) > 3 * math.hypot(s, u_d):
            if misfits:
                text = (f'a load-cell delay of {1e3 * (declared + est):+.3f} ms instead of the declared '
                        f'{1e3 * declared:.3f} ms would reduce the misfit; a delay and a model error (a missing '
                        'viscous branch) both lag the force in proportion to frequency, so only a calibration of '
                        'the load cell can tell them apart; nothing was applied')
            else:
                text = (f'the data prefer a load-cell delay of {1e3 * (declared + est):+.3f} +- {1e3 * s:.3f} ms, '
                        f'not the declared {1e3 * declared:.3f} +- {1e3 * u_d:.3f} ms '
                        f'({abs(est) / math.hypot(s, u_d):.1f} combined sigmas): check the calibration; nothing was '
                        'applied')
            out.append(FitWarning('calibration_disagrees', text, (DELAY,)))
    return out


SETTLED_CYCLES = 3   # seed 000: Berg's friction loop is steady after about three cycles


def short_block_warnings(fit) -> list:
    """Blocks analysed from fewer than SETTLED_CYCLES settling cycles (--settle-cycles below 3), or with fewer
    than SETTLED_CYCLES analysed cycles: the friction loop and the block offset are still settling there.
    """
    short = [b for b in fit.blocks if b.cycles and (b.skipped_cycles < SETTLED_CYCLES or b.cycles < SETTLED_CYCLES)]
    if not short:
        return []
    return [FitWarning('short_blocks', f'{len(short)} of {len(fit.blocks)} blocks have fewer than {SETTLED_CYCLES} '
                       'settling cycles before the analysed ones, or fewer than that many analysed: the friction '
                       'loop is not steady there and the friction parameters come out low (measured on seed 000\'s '
                       'joint, 3-cycle blocks with --settle-cycles 1, 10 seeds: x2 -4.9 %, F_fmax -5.7 %, K0 '
                       '+0.4 %, all in the same direction every time); record longer blocks',
                       ())]


def temperature_warnings(fit) -> list:
    """'temperature_disagrees' for each recording whose metadata and temperature channel disagree, or whose
    temperature is not the one the model's fixed parameters belong to (fitting.temperature).
    """
    out = []
    for name, record in (getattr(fit, 'temperature_records', None) or {}).items():
        for text in temperature_sentences(record, getattr(fit, 'model_temperature', None),
                                          getattr(fit, 'fixed', ()), name):
            out.append(FitWarning('temperature_disagrees', text))
    return out


def diagnosis_warnings(fit) -> list:
    """'non_stationary', 'outliers' and 'saturation' warnings of ``fit.diagnoses`` (fitting.diagnoses)."""
    found = getattr(fit, 'diagnoses', None) or {}
    out = []
    stds = [r.get('channel_std') for r in (getattr(fit, 'temperature_records', None) or {}).values()
            if r.get('channel_std')]
    text = drift_sentence(found.get('drift') or {}, max(stds) if stds else None)
    if text:
        out.append(FitWarning('non_stationary', text))
    units = {'force': (1.0, 'N'), 'displacement': (1e3, 'mm')}
    for name, channels in (found.get('outliers') or {}).items():
        for channel, test in channels.items():
            sigma = ((fit.noise_estimates.get(name) or {}).get(channel) or {}).get('sigma', math.nan)
            scale, unit = units[channel]
            out.append(FitWarning('outliers', outlier_sentence(channel, name, test, sigma * scale, unit,
                                                               test.get('dt', 1.0))))
    for name, channels in (found.get('saturation') or {}).items():
        for channel, flat in channels.items():
            scale, unit = (1e-3, 'kN') if channel == 'force' else units[channel]
            out.append(FitWarning('saturation', saturation_sentence(channel, name, flat, scale, unit)))
    return out


def extrapolation_warnings(fit) -> list:
    """'extrapolation' for each limit parameter the model's shape outside the measured band sets beyond its
    stated uncertainty (fitting.extrapolation).
    """
    out = []
    for name, u in fit.uncertainty.items():
        x = u.get('extrapolation')
        if x and x.get('warn'):
            factor, unit = paper_unit(fit.model, name)
            out.append(FitWarning('extrapolation', extrapolation_sentence(
                name, x, f'{u["value"] * factor:.4g} +- {u["sigma"] * factor:.2g} {unit}'), (name,)))
    return out


def verdict(fit, coords) -> list:
    """All warnings of ``fit`` (a ModelFit) in the order: misfit, identifiability, load cell, calibration,
    temperature.
    """
    misfit = misfit_warnings(fit)
    return (misfit + identifiability_warnings(fit, coords) + delay_warnings(fit)
            + calibration_warnings(fit, any(w.code == 'misfit' for w in misfit)) + short_block_warnings(fit)
            + temperature_warnings(fit) + diagnosis_warnings(fit) + extrapolation_warnings(fit))
