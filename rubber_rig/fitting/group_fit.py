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

"""One specimen state identified: the blocks of its recordings fitted by one model (``fit_group``), with the
uncertainty budget, the misfit test and the per-block quality that `fitting.identification` reports.

    blocks -> harmonic global search -> time-domain refinement (optionally with the load-cell delay as a
           parameter) -> uncertainty (GUM budget) -> per-block quality -> warnings (`verdict`)
"""
from __future__ import annotations

import math
import time

import numpy as np

from rubber_rig.models.modelfile import ModelSpec, named_model, parse_model

from .budget import add_budget, linearised_shift
from .calibration import corrected_force
from .diagnoses import drift_within_blocks, flat_tops, outlier_test
from .extrapolation import mark_extrapolations
from .inputnoise import berg_input_noise
from .metrics import window_properties
from .misfit import misfit_test
from .modelfit import ModelFit, TimeProblem, covariance, fit_time_model, jacobian, physical_uncertainty
from .noise import run_noise
from .search import DELAY, BlockTargets, coordinates, fit_harmonic_model
from .structure import residual_structure
from .verdict import notes, verdict

RESTART_CHI2 = 1.5   # a time-domain fit this far above noise tries other starts of the global search (a search
#                      heuristic; whether the final fit misfits is misfit.misfit_test's statistical decision)


def block_quality(spec: ModelSpec, blocks, forces: dict, runs: dict, measured: dict | None = None,
                  sigmas=None) -> list:
    """Per block: measured K_dyn, C_eq and the model's (analytic first harmonic and the model run over the
    measured displacement, ``forces`` recording -> model force), relative errors as seed 000 Eq. 28.
    ``measured``: recording -> force to measure the blocks on again (e.g. corrected for an estimated delay).
    ``sigmas``: (relative 1-sigma of K_dyn, of C_eq) per block from the load-cell noise, stored with each row.
    """
    t = BlockTargets.from_blocks(blocks, {})
    k = spec.first_harmonic(t.frequency, t.amplitude, t.mean)
    rows = []
    for i, b in enumerate(blocks):
        w = 2 * np.pi * b.frequency
        kd, ce = b.k_dyn, b.c_eq
        if measured and b.recording in measured:
            run = runs[b.recording]
            hp = window_properties(run.displacement, measured[b.recording], run.dt, b.start, b.stop, b.frequency)
            kd, ce = hp['k_dyn'], hp['c_eq']
        row = {'recording': b.recording, 'block': b.index, 'frequency': b.frequency, 'amplitude': b.amplitude,
               'mean': b.mean, 'cycles': b.cycles,
               'measured': {'k_dyn': kd, 'c_eq': ce, 'loss_angle': b.loss_angle, 'energy': b.energy},
               'analytic': {'k_dyn': float(abs(k[i])), 'c_eq': float(k[i].imag / w),
                            'e_k': float(abs(k[i]) / kd - 1), 'e_c': float(k[i].imag / w / ce - 1)}}
        force = forces.get(b.recording)
        if force is not None:
            run = runs[b.recording]
            hp = window_properties(run.displacement, force, run.dt, b.start, b.stop, b.frequency)
            row['simulated'] = {'k_dyn': hp['k_dyn'], 'c_eq': hp['c_eq'],
                                'e_k': hp['k_dyn'] / kd - 1, 'e_c': hp['c_eq'] / ce - 1}
        if sigmas is not None:
            row['measured']['rel_sigma_k'], row['measured']['rel_sigma_c'] = float(sigmas[0][i]), float(sigmas[1][i])
        rows.append(row)
    return rows


def truth_of(spec: ModelSpec, runs) -> dict | None:
    """The true values of ``spec``'s parameters when a recording's metadata holds its specimen as a model
    (simulated recordings) with the same elements in the same order; else None.
    """
    for run in runs:
        specimen = (run.metadata or {}).get('specimen')
        if not isinstance(specimen, dict):
            continue
        try:
            if 'elements' in specimen:
                true = parse_model(specimen, run.name)
            elif 'parameter_set' in specimen:
                true = named_model(specimen['parameter_set'])
            else:
                continue
        except ValueError:
            continue
        if [e.type for e in true.elements] != [e.type for e in spec.elements]:
            return None
        canonical = true.canonical_names()     # the fit's repeated elements are in this order too
        tv = {canonical[n]: v for n, v in true.values().items()}
        return {n: tv[n] for n, _, _ in spec.free() if n in tv}
    return None


def fit_group(spec: ModelSpec, items, temperature, method='time', estimate_delay=True, w_k=100.0, w_c=1.0,
              seed=0, points_per_block=200, progress=None, calibration=None) -> ModelFit:
    """Identify ``spec``'s free parameters from [(run, blocks)] of one specimen state: a global search on the
    blocks' first harmonics, then (method 'time') the time-domain refinement, the uncertainty budget, the
    per-block quality and the warnings.
    """
    t0 = time.perf_counter()
    blocks = [b for _, bl, _ in items for b in bl]
    # each recording's noise with its blocks' excitation harmonics removed (noise.band_noise), once per fit
    estimates = {run.name: run_noise(run, bl) for run, bl, _ in items}
    noise = {name: e['force'].sigma for name, e in estimates.items()}
    known = {name: cal.get('delay', 0.0) for name, cal in (calibration or {}).items()}
    targets = BlockTargets.from_blocks(blocks, noise, known)
    dt = min(run.dt for run, _, _ in items)
    n_free = len(spec.free()) + (1 if estimate_delay and method == 'time' else 0)
    if 2 * len(blocks) < n_free + 1:
        raise ValueError(f'{len(blocks)} usable blocks give {2 * len(blocks)} numbers (K_dyn, C_eq); the model has '
                         f'{n_free} free parameters: record more blocks over frequency and amplitude')
    # the harmonic global search has the delay too (a late load cell adds a phase w d that would otherwise
    # push the loss parameters far from the optimum the time-domain refinement starts near)
    hc = coordinates(spec, targets, dt, delay=estimate_delay and method == 'time')
    if progress:
        progress(0.05, 'global search (first harmonics)')
    z_h, ls_h = fit_harmonic_model(spec, hc, targets, w_k, w_c, seed=seed)
    timings = {'harmonic_s': time.perf_counter() - t0}
    search = (hc, z_h, ls_h, targets, w_k, w_c)
    if method == 'harmonic':
        sol = _harmonic_solution(spec, items, blocks, search, points_per_block, known, estimates)
    else:
        sol = _time_solution(spec, items, search, points_per_block, known, estimate_delay, seed, progress, estimates)
        timings['time_fit_s'] = time.perf_counter() - t0 - timings['harmonic_s']
    fit = _assemble(spec, sol, items, blocks, targets, noise, known, temperature, method, calibration, estimates)
    fit.timings = {**timings, 'total_s': time.perf_counter() - t0}
    return fit


class _Solution:
    """What either method found: coordinates and optimum z, the values, their uncertainty and correlation,
    chi^2 and dof, the number of fitted points, the estimated delay, the misfit test, the time problem and its
    predicted forces, the delay check and the parameters the refinement left at its bounds.
    """

    def __init__(self, **kw):
        self.limited, self.delay_shift, self.delay_check, self.predicted, self.messages = [], None, None, None, []

        self.__dict__.update(kw)


def _harmonic_solution(spec, items, blocks, search, points_per_block, known, estimates) -> _Solution:
    """The first-harmonic optimum as the answer (method 'harmonic')."""
    hc, z_h, ls_h, targets, w_k, w_c = search
    values = hc.values(z_h)
    unc, corr, chi2, dof = harmonic_uncertainty(hc, z_h, ls_h, targets, w_k, w_c)
    share = np.array([sum(b.recording == run.name for b in blocks) for run, _, _ in items], float)
    u = [estimates[run.name]['force'].variance_u for run, _, _ in items]
    misfit = misfit_test(chi2, dof, float(np.sqrt(np.sum((share / share.sum() * np.array(u)) ** 2))))
    problem = TimeProblem(spec.with_values(values), items, points_per_block, known, estimates)
    return _Solution(coords=hc, z=z_h, values=values, unc=unc, corr=corr, chi2=chi2, dof=dof,
                     n_points=2 * len(blocks), delay=0.0, misfit=misfit, problem=problem,
                     predicted=problem.predict({}))


def _time_solution(spec, items, search, points_per_block, known, estimate_delay, seed, progress,
                   estimates) -> _Solution:
    """The time-domain refinement from the first-harmonic optimum (method 'time'), with its uncertainty."""
    hc, z_h, _, targets, w_k, w_c = search
    problem = TimeProblem(spec, items, points_per_block, known, estimates)
    coords = coordinates(spec, targets, min(run.dt for run, _, _ in items), delay=estimate_delay)
    if progress:
        progress(0.4, 'time-domain fit')
    messages = []
    ls, (lo, hi) = fit_time_model(problem, coords, coords.z_of(dict(hc.values(z_h))))
    dof_t = max(problem.m - len(coords.names) - len(problem.block_rows), 1)
    if float(ls.fun @ ls.fun) / dof_t > RESTART_CHI2:
        # a misfit may be a wrong basin of the first-harmonic search (e.g. a large negative cubic term
        # standing in for friction): try other starts, refine the most promising if it beats this one
        better = _other_start(spec, hc, targets, problem, coords, seed, w_k, w_c, float(ls.fun @ ls.fun),
                              coords.values(ls.x))
        if better is not None:
            ls2, bounds2 = fit_time_model(problem, coords, better)
            if ls2.fun @ ls2.fun < ls.fun @ ls.fun:
                ls, (lo, hi) = ls2, bounds2
                messages.append('a second start of the global search gave the better fit')
    z = ls.x
    if ls.status == 0:
        messages.append('time-domain fit stopped before converging (evaluation limit)')
    if progress:
        progress(0.8, 'uncertainty')

    def fun(zz):
        return problem.residuals(coords.values(zz))
    r = fun(z)
    jac = jacobian(fun, z)
    cov_n, cov_b, chi2, dof = covariance(jac, r, problem.block_rows, n_offsets=len(problem.block_rows))
    unc, corr = physical_uncertainty(coords, z, cov_n, cov_b, len(problem.block_rows))
    values = coords.values(z)
    predicted = problem.predict(values)     # the fitted model over every recording, once
    sol = _Solution(coords=coords, z=z, values=values, unc=unc, corr=corr, chi2=chi2, dof=dof, n_points=problem.m,
                    delay=float(values.get(DELAY, 0.0)), misfit=time_misfit(problem, values, r, dof, predicted),
                    problem=problem, predicted=predicted, limited=_at_bounds(coords, z, lo, hi), messages=messages)
    if DELAY not in coords.names:
        sol.delay_shift, sol.delay_check = delay_sensitivity(problem, coords, z, jac, r, chi2 / max(dof, 1),
                                                             predicted)
    return sol


def diagnose(fit, runs: dict, forces: dict) -> dict:
    """The fit's named diagnoses (fitting.diagnoses): {'drift': drift inside the blocks, 'outliers': {recording:
    {channel: test}}, 'saturation': {recording: {channel: flat tops}}} (only what was found, besides drift).
    ``forces``: recording name -> the fitted model's force over its displacement.
    """
    out = {'drift': drift_within_blocks(fit.blocks, runs, forces, fit.noise), 'outliers': {}, 'saturation': {}}
    for name, run in runs.items():
        for channel in ('force', 'displacement'):
            test = outlier_test((fit.noise_estimates.get(name) or {}).get(channel) or {})
            if test:
                out['outliers'].setdefault(name, {})[channel] = {**test, 'dt': run.dt}
            flat = flat_tops(getattr(run, channel))
            if flat:
                out['saturation'].setdefault(name, {})[channel] = flat
    return out


def _assemble(spec, sol, items, blocks, targets, noise, known, temperature, method, calibration,
              estimates) -> ModelFit:
    """The ModelFit of a solution: canonical names, the GUM budget, per-block quality, warnings and notes."""
    coords, values, unc = sol.coords, sol.values, sol.unc
    runs = {run.name: run for run, _, _ in items}
    # repeated elements (two Maxwell branches) in canonical order, by relaxation time: the labels the
    # optimiser happened to give them mean nothing (the correlation matrix keeps its positions)
    rename = spec.canonical_names({**spec.values(), **{k: v for k, v in values.items() if k != DELAY}})
    values = {rename.get(k, k): v for k, v in values.items()}
    unc = {rename.get(k, k): u for k, u in unc.items()}
    names = [rename.get(n, n) for n in coords.names]
    fitted = spec.with_values({k: v for k, v in values.items() if k != DELAY})
    params = {n: float(values[n]) for n in names}
    cal = next(iter((calibration or {}).values()), {})
    add_budget(unc, dict(zip(coords.names, coords.kinds, strict=True)),
               {n: spec.param_spec(n).scale for n in coords.names if n != DELAY}, cal,
               delay_shift=(None if sol.delay_shift is None
                            else {rename.get(k, k): v for k, v in sol.delay_shift.items()}),
               delay_estimated=DELAY in coords.names,
               units={rename.get(n, n): spec.param_spec(n).unit for n in coords.names if n != DELAY},
               input_noise=(berg_input_noise(fitted, params, _displacement_noise(estimates)) if method == 'time'
                            else None))
    band = mark_extrapolations(fitted, {n: v for n, v in params.items() if n != DELAY}, blocks, unc)
    forces = dict(zip(runs, sol.predicted, strict=True))
    # with an estimated delay the blocks are compared as the specimen behaved: the measured force corrected
    # for it (compared as measured, a late load cell's phase would remove most of the loss at high frequency
    # and turn small absolute differences into large relative C_eq errors)
    total = {name: sol.delay + known.get(name, 0.0) for name in runs}
    measured = {name: corrected_force(run.force, run.dt, total[name], 1.0) for name, run in runs.items()
                if total[name]} or None
    quality = block_quality(fitted, blocks, forces, runs, measured=measured,
                            sigmas=(targets.rel_sigma_k, targets.rel_sigma_c))
    fit = ModelFit(model=fitted, temperature=temperature, runs=list(runs), blocks=blocks, method=method,
                   parameters=params, uncertainty=unc, correlation=sol.corr.tolist(), chi2=float(sol.chi2),
                   dof=int(sol.dof), n_points=int(sol.n_points), noise=noise,
                   load_cell=_load_cell_record(cal, params, unc, sol.delay_check), quality=quality,
                   messages=sol.messages)
    fit.misfit = sol.misfit
    fit.band = band
    fit.noise_estimates = {name: {k: e.as_dict() for k, e in est.items()} for name, est in estimates.items()}
    fit.bounds_hit = [rename.get(n, n) for n in _at_bounds(coords, sol.z, coords.lo, coords.hi)]
    if method == 'time':
        fit.refinement_limited = [rename.get(n, n) for n in sol.limited if rename.get(n, n) not in fit.bounds_hit]
    fit.truth = truth_of(spec, [run for run, _, _ in items])
    fit.temperature_records = {run.name: run.temperature_record for run, _, _ in items if run.temperature_record}
    fit.model_temperature = spec.meta.get('temperature')
    free = {n for n, _, _ in spec.free()}
    fit.fixed = [n for n in spec.values() if n not in free]
    fit.diagnoses = diagnose(fit, runs, forces)
    fit.warnings = verdict(fit, coords)
    fit.notes = notes(fit)
    return fit


def _displacement_noise(estimates: dict) -> float:
    """The largest displacement noise sigma [m] of the fit's recordings (noise.run_noise), 0 if none."""
    return max((float(e['displacement'].sigma) for e in estimates.values() if e.get('displacement')), default=0.0)


def _load_cell_record(cal: dict, params: dict, unc: dict, delay_check) -> dict:
    """ModelFit.load_cell: the declared calibration applied, the delay estimated (if it was) and its check."""
    return {'delay': cal.get('delay', 0.0), 'gain': cal.get('gain', 1.0),
            'calibration_source': cal.get('source', 'none'),
            'delay_estimated': params.get(DELAY), 'delay_sigma': unc.get(DELAY, {}).get('sigma'),
            'delay_interval_95': unc.get(DELAY, {}).get('interval_95'),
            'gain_u': cal.get('gain_u'), 'delay_u': cal.get('delay_u'),
            'delay_check': delay_check, 'displacement_gain': cal.get('displacement_gain', 1.0),
            'displacement_gain_u': cal.get('displacement_gain_u'),
            'temperature_u': cal.get('temperature_u')}


def delay_sensitivity(problem: TimeProblem, coords, z, jac, r, inflation: float, preds) -> tuple:
    """(shift, check) of a time-domain fit whose load-cell delay was held at the declared value.

    shift: parameter name -> d(parameter)/d(delay) [unit/s], linearised at the optimum (Gauss-Newton:
    dz = -(J^T J)^-1 J^T dr/dd), for the declared delay's uncertainty in the budget.
    check: the delay the data would prefer beyond the declared one, as a diagnostic that is never applied:
    {'estimate' [s], 'sigma' [s]} from one Gauss-Newton step with the delay freed (its sigma is the marginal
    one, from the Schur complement of the information matrix, inflated by the misfit).
    """
    h = 1e-2 * min(run.dt for run, *_ in problem.items)
    jd = (problem.residuals_from(preds, h) - problem.residuals_from(preds, -h)) / (2 * h)
    shift, _ = linearised_shift(coords, z, jac, jd)
    bread = np.linalg.pinv(jac.T @ jac)
    b = jac.T @ jd
    schur = float(jd @ jd - b @ bread @ b)
    if schur <= 0:
        return shift, None
    estimate = -float(jd @ r - b @ bread @ (jac.T @ r)) / schur
    return shift, {'estimate': estimate, 'sigma': math.sqrt(max(1.0, inflation) / schur)}


def time_misfit(problem: TimeProblem, values: dict, r, dof: int, predictions) -> dict:
    """The misfit test (misfit.misfit_test) of a time-domain fit with residual ``r`` (load-cell noise units).

    The noise the residual is judged against is the load cell's plus the displacement noise carried through
    the model (TimeProblem.input_noise: errors in variables); each recording's chi^2 share is rescaled to that
    sum. The noise estimate's uncertainty is each recording's (noise.band_noise's variance_u) for its load
    cell share, combined over recordings by their share of the points.
    """
    carried = problem.input_noise(values, predictions)
    chi2, u2, total = 0.0, 0.0, problem.m
    inputs, shares, lag1 = {}, [], []
    items = zip(problem.items, problem.item_rows, carried, problem.noise_estimates, strict=True)
    for (run, _, _, _, _, sigma), rows, (s_in, rho), est in items:
        share = sigma ** 2 / (sigma ** 2 + s_in ** 2)
        shares.append(share)
        lag1.append((1.0 - share) * rho)       # a correct model's residual correlates this much (input noise)
        part = r[rows]
        chi2 += float(part @ part) * share
        n = part.size / max(total, 1)
        u2 += (n * share * est['force'].variance_u) ** 2
        inputs[run.name] = s_in
    out = misfit_test(chi2, dof, math.sqrt(u2))
    out['input_noise'] = inputs
    out['chi2_load_cell_only'] = float(r @ r)
    out['structure'] = residual_structure(problem, r, shares, math.sqrt(u2), lag1, n_free=len(values))
    return out


def _other_start(spec, hc, targets, problem, coords, seed, w_k, w_c, chi2_now, current):
    """Coordinates of the best alternative start for the time-domain fit, or None: two more global searches
    on the first harmonics (other seeds; one seeded with the current optimum with its signed terms at zero),
    each judged by one model run over the loops.
    """
    best, best_chi2 = None, chi2_now
    zeroed = {n: (0.0 if k == 'lin' else current[n]) for n, k in zip(hc.names, hc.kinds, strict=True)}
    for k, hint in ((1, zeroed), (2, None)):
        z_alt, _ = fit_harmonic_model(spec, hc, targets, w_k, w_c, seed=seed + k, start=hint)
        start = hc.values(z_alt)
        start.setdefault(DELAY, 0.0)
        z0 = coords.z_of({n: start.get(n, 0.0) for n in coords.names})
        r = problem.residuals(coords.values(z0))
        if float(r @ r) < best_chi2:
            best, best_chi2 = z0, float(r @ r)
    return best


def harmonic_uncertainty(coords, z, ls, targets, w_k, w_c):
    """(uncertainty, correlation, chi2, dof) of a harmonic (Eq. 29) fit.

    With the blocks' measurement noise known (``targets.rel_sigma_*`` > 0): chi2 is in units of it, and the
    covariance of the weighted estimator is the sandwich (J^T W J)^-1 J^T W S W J (J^T W J)^-1 with the
    noise covariance S inflated by max(1, chi2/dof). Without it (a table without sigma columns) the
    scatter s^2 = sum r^2 / dof of the weighted errors scales (J^T W J)^-1 and chi2 is that weighted sum.
    Either way the blocks are clusters for the jackknife covariance, as in the time domain.
    """
    nb = len(targets)
    rows = [[i, i + nb] for i in range(nb)]
    jac, r = ls.jac, ls.fun
    cov_n, cov_b, chi2_w, dof = covariance(jac, r, rows)
    bread = np.linalg.pinv(jac.T @ jac)
    if np.all(targets.rel_sigma_k > 0) and np.all(targets.rel_sigma_c > 0):
        # residual i is sqrt(w_i) e_i with e_i's noise sigma_i: in noise units r_i / (sqrt(w_i) sigma_i)
        scale = np.concatenate([np.sqrt(w_k) * targets.rel_sigma_k, np.sqrt(w_c) * targets.rel_sigma_c])
        chi2 = float(np.sum((r / scale) ** 2))
        meat = (jac * scale[:, None] ** 2).T @ jac
        cov_noise = bread @ meat @ bread * max(1.0, chi2 / max(dof, 1))
    else:
        chi2 = chi2_w
        cov_noise = bread * chi2_w / max(dof, 1)
    unc, corr = physical_uncertainty(coords, z, cov_noise, cov_b, nb)
    return unc, corr, chi2, dof


def _at_bounds(coords, z, lo, hi) -> list:
    """Free parameters (fractional orders excepted: 1 is a legitimate value) within 0.1 % of a bound."""
    span = coords.hi - coords.lo
    near = (z - lo < 1e-3 * span) | (hi - z < 1e-3 * span)
    return [n for n, k, hit in zip(coords.names, coords.kinds, near, strict=True) if hit and k != 'order']
