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

"""From recordings to identified models: any model file, load-cell calibration, verdict and model ranking.

    runs -> load-cell calibration (delay, gain) -> blocks -> per temperature: harmonic global search
         -> time-domain refinement (optionally with the load-cell delay as a parameter) -> uncertainty
         -> per-block quality -> warnings (`verdict`)

`fit_model` identifies one model, `compare_models` several on the same data and ranks them by AIC and BIC
(chi^2 in units of the measured noise, so both count the data the same way for every candidate).
"""
from __future__ import annotations

import copy
import math
import time

import numpy as np
import yaml

from rubber_rig.models.modelfile import ModelSpec, named_model, parse_model, resolve_model

from .blocks import noise_level, noise_variance_uncertainty, split_blocks
from .budget import add_budget, linearised_shift
from .metrics import window_properties
from .modelfit import (
    DELAY,
    BlockTargets,
    ModelFit,
    TimeProblem,
    coordinates,
    covariance,
    fit_harmonic_model,
    fit_time_model,
    jacobian,
    physical_uncertainty,
)
from .structure import residual_structure
from .verdict import misfit_test, notes, verdict

METHODS = ('harmonic', 'time')
RESTART_CHI2 = 1.5   # a time-domain fit this far above noise tries other starts of the global search (a search
#                      heuristic; whether the final fit misfits is verdict.misfit_test's statistical decision)
AIC_TIE = 2.0     # models within this many AIC units of the best are equally supported (Burnham & Anderson)


def load_cell_calibration(run, delay=None, gain=None) -> tuple:
    """(delay [s], gain [-], source) for ``run``: the given values, else the recording's rig configuration
    (``load_cell_delay``, ``load_cell_gain``: the simulated rig's ``rig_config`` mapping, or the recorder's
    ``metadata.rig_configuration`` YAML/JSON text a launch file sets), else (0, 1).
    """
    cfg = _rig_config(run)
    sources = []
    if delay is None and cfg.get('load_cell_delay') is not None:
        delay = cfg['load_cell_delay']
        sources.append('recording metadata')
    if gain is None and cfg.get('load_cell_gain') is not None:
        gain = cfg['load_cell_gain']
        sources.append('recording metadata')
    given = (delay is not None or gain is not None) and not sources
    delay = 0.0 if delay is None else float(delay)
    gain = 1.0 if gain is None else float(gain)
    if not (math.isfinite(delay) and abs(delay) < 1.0):
        raise ValueError(f'{run.name}: load-cell delay must be a finite time below 1 s, got {delay!r}')
    if not (math.isfinite(gain) and gain > 0):
        raise ValueError(f'{run.name}: load-cell gain must be > 0, got {gain!r}')
    return delay, gain, 'given' if given else (sources[0] if sources else 'none')


def corrected_force(force, dt, delay, gain):
    """The specimen force from a load cell that reads gain x the force of ``delay`` s earlier:
    F(t) = F_measured(t + delay) / gain, linear interpolation; the last samples repeat the edge.
    """
    f = np.asarray(force, float)
    if delay:
        n = np.arange(f.size, dtype=float)
        f = np.interp(n + delay / dt, n, f)
    return f / gain


def declared_uncertainties(run, gain_u=None, delay_u=None, displacement_gain_u=None, temperature_u=None) -> dict:
    """{'gain_u', 'delay_u', 'displacement_gain_u', 'temperature_u'}: the standard uncertainties of the load
    cell's gain [-] and delay [s] as given, else as the recording's rig configuration declares them
    (``load_cell_gain_u``, ``load_cell_delay_u``), and of the displacement transducer's gain [-] and the
    temperature sensor [K] likewise (``displacement_gain_u``, ``temperature_u``); None where nothing is
    declared (a negative value declares nothing).
    """
    cfg = _rig_config(run)
    out = {}
    for key, given in (('gain_u', gain_u), ('delay_u', delay_u), ('displacement_gain_u', displacement_gain_u),
                       ('temperature_u', temperature_u)):
        v = given if given is not None else cfg.get(key if key.startswith(('displacement', 'temperature'))
                                                    else f'load_cell_{key}')
        try:
            v = None if v is None else float(v)
        except (TypeError, ValueError):
            v = None
        out[key] = v if v is not None and math.isfinite(v) and v >= 0 else None
    return out


def _rig_config(run) -> dict:
    meta = run.metadata or {}
    cfg = meta.get('rig_config') or meta.get('rig_configuration') or {}
    if isinstance(cfg, str):
        try:
            cfg = yaml.safe_load(cfg)
        except yaml.YAMLError:
            cfg = {}
    return cfg if isinstance(cfg, dict) else {}


def calibrate(run, delay=None, gain=None, gain_u=None, delay_u=None, **declared):
    """The run with its force divided by the known gain, and the calibration (delay, gain, their declared
    standard uncertainties or None, source). A known delay is not taken out of the data (interpolating between
    samples would filter the noise and fake a lower noise level): the fit compares the model at t - delay.
    """
    d, g, source = load_cell_calibration(run, delay, gain)
    g_x = _rig_config(run).get('displacement_gain', 1.0)
    try:
        g_x = float(g_x)
    except (TypeError, ValueError):
        g_x = math.nan
    if not (math.isfinite(g_x) and g_x > 0):
        raise ValueError(f'{run.name}: displacement gain must be > 0, got {g_x!r}')
    cal = {'delay': d, 'gain': g, 'displacement_gain': g_x, 'source': source,
           **declared_uncertainties(run, gain_u, delay_u, **declared)}
    if d == 0.0 and g == 1.0 and g_x == 1.0:
        return run, cal
    out = copy.copy(run)
    out.force = np.asarray(run.force, float) / g
    out.displacement = np.asarray(run.displacement, float) / g_x
    return out, cal


def _temp_key(t):
    return None if t is None else round(float(t) * 2.0) / 2.0


def quasi_static_windows(run) -> list:
    """Sample ranges (start, stop) of the run's triangle blocks (block index + recorded program)."""
    if run.block_index is None or not run.program_blocks:
        return []
    bi = np.asarray(run.block_index)
    change = np.flatnonzero(np.diff(bi) != 0) + 1
    bounds = np.concatenate([[0], change, [bi.size]])
    out = []
    for s, e in zip(bounds[:-1], bounds[1:], strict=True):
        k = int(bi[s])
        if 0 <= k < len(run.program_blocks) and run.program_blocks[k].get('waveform') == 'triangle' and e - s > 10:
            out.append((int(s), int(e)))
    return out


def split_runs(runs, settle_cycles=3, min_cycles=2):
    """{temperature key: [(run, blocks, quasi-static windows)]} and messages."""
    groups, messages = {}, []
    for run in runs:
        messages.extend(run.messages)
        if not run.usable():
            messages.append(f'{run.name}: no displacement or no force channel; not fitted')
            continue
        rep = split_blocks(run.displacement, run.force, run.dt, block_index=run.block_index,
                           program_blocks=run.program_blocks, settle_cycles=settle_cycles,
                           min_cycles=min_cycles, recording=run.name)
        messages.extend(rep.messages)
        if rep.blocks:
            groups.setdefault(_temp_key(run.temperature), []).append((run, rep.blocks, quasi_static_windows(run)))
    return groups, messages


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
    """Identify ``spec``'s free parameters from [(run, blocks)] of one specimen state."""
    t0 = time.perf_counter()
    blocks = [b for _, bl, _ in items for b in bl]
    runs = {run.name: run for run, _, _ in items}
    noise = {run.name: noise_level(run.force) for run, _, _ in items}
    known = {name: cal.get('delay', 0.0) for name, cal in (calibration or {}).items()}
    targets = BlockTargets.from_blocks(blocks, noise, known)
    dt = min(run.dt for run, _, _ in items)
    free = spec.free()
    n_free = len(free) + (1 if estimate_delay and method == 'time' else 0)
    if 2 * len(blocks) < n_free + 1:
        raise ValueError(f'{len(blocks)} usable blocks give {2 * len(blocks)} numbers (K_dyn, C_eq); the model has '
                         f'{n_free} free parameters: record more blocks over frequency and amplitude')
    # the harmonic global search has the delay too (a late load cell adds a phase w d that would otherwise
    # push the loss parameters far from the optimum the time-domain refinement starts near)
    with_delay = estimate_delay and method == 'time'
    hc = coordinates(spec, targets, dt, delay=with_delay)
    if progress:
        progress(0.05, 'global search (first harmonics)')
    z_h, ls_h = fit_harmonic_model(spec, hc, targets, w_k, w_c, seed=seed)
    values = hc.values(z_h)
    timings = {'harmonic_s': time.perf_counter() - t0}
    messages = []
    delay_shift, delay_check = None, None
    if method == 'harmonic':
        unc, corr, chi2, dof = harmonic_uncertainty(hc, z_h, ls_h, targets, w_k, w_c)
        share = np.array([sum(b.recording == run.name for b in blocks) for run, _, _ in items], float)
        u = [noise_variance_uncertainty(run.force) for run, _, _ in items]
        misfit = misfit_test(chi2, dof, float(np.sqrt(np.sum((share / share.sum() * np.array(u)) ** 2))))
        coords, z, n_points, delay = hc, z_h, 2 * len(blocks), 0.0
        problem = TimeProblem(spec.with_values(values), items, points_per_block, known)
    else:
        problem = TimeProblem(spec, items, points_per_block, known)
        coords = coordinates(spec, targets, dt, delay=estimate_delay)
        start = dict(values)
        if progress:
            progress(0.4, 'time-domain fit')
        ls, (lo, hi) = fit_time_model(problem, coords, coords.z_of(start))
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
        limited = _at_bounds(coords, z, lo, hi)
        if ls.status == 0:
            messages.append('time-domain fit stopped before converging (evaluation limit)')
        timings['time_fit_s'] = time.perf_counter() - t0 - timings['harmonic_s']
        if progress:
            progress(0.8, 'uncertainty')

        def fun(zz):
            return problem.residuals(coords.values(zz))
        r = fun(z)
        jac = jacobian(fun, z)
        cov_n, cov_b, chi2, dof = covariance(jac, r, problem.block_rows, n_offsets=len(problem.block_rows))
        unc, corr = physical_uncertainty(coords, z, cov_n, cov_b, len(problem.block_rows))
        values = coords.values(z)
        n_points = problem.m
        delay = float(values.get(DELAY, 0.0))
        predicted = problem.predict(values)     # the fitted model over every recording, once
        misfit = time_misfit(problem, values, r, dof, predicted)
        if DELAY not in coords.names:
            delay_shift, delay_check = delay_sensitivity(problem, coords, z, jac, r, chi2 / max(dof, 1), predicted)
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
               delay_shift=None if delay_shift is None else {rename.get(k, k): v for k, v in delay_shift.items()},
               delay_estimated=DELAY in coords.names,
               units={rename.get(n, n): spec.param_spec(n).unit for n in coords.names if n != DELAY})
    if method == 'harmonic':
        predicted = problem.predict({})
    forces = dict(zip(runs, predicted, strict=True))
    # with an estimated delay the blocks are compared as the specimen behaved: the measured force corrected
    # for it (compared as measured, a late load cell's phase would remove most of the loss at high frequency
    # and turn small absolute differences into large relative C_eq errors)
    total = {name: delay + known.get(name, 0.0) for name in runs}
    measured = {name: corrected_force(run.force, run.dt, total[name], 1.0) for name, run in runs.items()
                if total[name]} or None
    quality = block_quality(fitted, blocks, forces, runs, measured=measured,
                            sigmas=(targets.rel_sigma_k, targets.rel_sigma_c))
    fit = ModelFit(model=fitted, temperature=temperature, runs=list(runs), blocks=blocks, method=method,
                   parameters=params, uncertainty=unc, correlation=corr.tolist(), chi2=float(chi2), dof=int(dof),
                   n_points=int(n_points), noise=noise,
                   load_cell={'delay': cal.get('delay', 0.0), 'gain': cal.get('gain', 1.0),
                              'calibration_source': cal.get('source', 'none'),
                              'delay_estimated': params.get(DELAY), 'delay_sigma': unc.get(DELAY, {}).get('sigma'),
                              'delay_interval_95': unc.get(DELAY, {}).get('interval_95'),
                              'gain_u': cal.get('gain_u'), 'delay_u': cal.get('delay_u'),
                              'delay_check': delay_check, 'displacement_gain': cal.get('displacement_gain', 1.0),
                              'displacement_gain_u': cal.get('displacement_gain_u'),
                              'temperature_u': cal.get('temperature_u')},
                   quality=quality, messages=messages)
    fit.misfit = misfit
    fit.bounds_hit = [rename.get(n, n) for n in _at_bounds(coords, z, coords.lo, coords.hi)]
    if method == 'time':
        fit.refinement_limited = [rename.get(n, n) for n in limited if rename.get(n, n) not in fit.bounds_hit]
    fit.truth = truth_of(spec, [run for run, _, _ in items])
    fit.warnings = verdict(fit, coords)
    fit.notes = notes(fit)
    fit.timings = {**timings, 'total_s': time.perf_counter() - t0}
    return fit


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
    """The misfit test (verdict.misfit_test) of a time-domain fit with residual ``r`` (load-cell noise units).

    The noise the residual is judged against is the load cell's plus the displacement noise carried through
    the model (TimeProblem.input_noise: errors in variables); each recording's chi^2 share is rescaled to that
    sum. The noise estimate's uncertainty is each recording's (blocks.noise_variance_uncertainty) for its load
    cell share, combined over recordings by their share of the points.
    """
    carried = problem.input_noise(values, predictions)
    chi2, u2, total = 0.0, 0.0, problem.m
    inputs, shares, lag1 = {}, [], []
    for (run, _, _, force, _, sigma), rows, (s_in, rho) in zip(problem.items, problem.item_rows, carried,
                                                               strict=True):
        share = sigma ** 2 / (sigma ** 2 + s_in ** 2)
        shares.append(share)
        lag1.append((1.0 - share) * rho)       # a correct model's residual correlates this much (input noise)
        part = r[rows]
        chi2 += float(part @ part) * share
        n = part.size / max(total, 1)
        u2 += (n * share * noise_variance_uncertainty(force)) ** 2
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


def fit_model(runs, model='zener_berg', method='time', load_cell_delay=None, load_cell_gain=None,
              estimate_delay=False, settle_cycles=3, min_cycles=2, seed=0, w_k=100.0, w_c=1.0,
              progress=None, load_cell_gain_u=None, load_cell_delay_u=None, displacement_gain_u=None,
              temperature_u=None) -> tuple:
    """Identify ``model`` (model file, named model, parameter set or ModelSpec) from ``runs`` (RunData), one
    fit per temperature. Returns (fits, messages).

    The load cell's calibration (delay, gain and their standard uncertainties) is declared: given here, else
    the recordings' rig configuration. It is applied, never fitted away: the delay the data would prefer is a
    diagnostic (``load_cell['delay_check']``, a warning when it disagrees with the declared one).
    ``estimate_delay`` makes the delay a fit parameter instead (never below zero in total), for a load cell
    whose timing nobody measured; the fit then warns whenever the estimate is not zero. Likewise the
    displacement transducer's gain uncertainty and the temperature sensor's (``displacement_gain_u``,
    ``temperature_u``; the displacement gain itself comes from the rig configuration).
    """
    if method not in METHODS:
        raise ValueError(f'unknown fit method {method!r} (use one of {", ".join(METHODS)})')
    spec = resolve_model(model)
    if not spec.free():
        raise ValueError(f'model {spec.name or model!r}: every parameter is fixed; nothing to fit')
    calibrated, cals = [], {}
    for run in runs:
        if run.usable():
            run, cal = calibrate(run, load_cell_delay, load_cell_gain, load_cell_gain_u, load_cell_delay_u,
                                 displacement_gain_u=displacement_gain_u, temperature_u=temperature_u)
            cals[run.name] = cal
        calibrated.append(run)
    groups, messages = split_runs(calibrated, settle_cycles, min_cycles)
    if not groups:
        raise ValueError('no usable blocks in any recording: ' + '; '.join(messages))
    fits = []
    order = sorted(groups.items(), key=lambda kv: (kv[0] is None, kv[0] or 0))
    for n, (temp, items) in enumerate(order):
        def stage(frac, what, n=n, temp=temp):
            if progress is not None:
                progress((n + frac) / len(order), f'{_label(temp)}: {what}')
        try:
            fit = fit_group(spec, items, temp, method, estimate_delay, w_k, w_c, seed, progress=stage,
                            calibration={run.name: cals[run.name] for run, _, _ in items})
        except ValueError as exc:
            messages.append(f'{_label(temp)}: not fitted: {exc}')
            continue
        fits.append(fit)
    if progress is not None:
        progress(1.0, 'done')
    if not fits:
        raise ValueError('nothing could be fitted: ' + '; '.join(messages))
    return fits, messages


def compare_models(fits_by_model: dict) -> list:
    """Rank candidate models fitted to the same data: per temperature, rows sorted by BIC with delta BIC /
    delta AIC to the best, BIC (Schwarz) and Akaike weights, and a sentence saying what the data support.

    The selected model is the lowest BIC. BIC is consistent: with the true model among the candidates it
    is chosen with a probability that goes to 1 as the data grow, which is what identifying a specimen's
    physics asks for. AIC aims at prediction and keeps an unneeded nested parameter in about 16 % of data
    sets (P(chi2_1 > 2)); its choice is reported beside it (the simplest model within ``AIC_TIE`` of the
    lowest AIC, as models that close are equally supported) and the sentence says when the two disagree.
    """
    temps = {}
    for name, fits in fits_by_model.items():
        for f in fits:
            temps.setdefault(f.temperature, []).append((name, f))
    out = []
    for temp, rows in temps.items():
        rows.sort(key=lambda nf: nf[1].bic)
        best_aic, best_bic = min(f.aic for _, f in rows), rows[0][1].bic
        table = [{'model': name, 'n_params': f.n_params, 'chi2_per_dof': f.chi2_per_dof, 'aic': f.aic, 'bic': f.bic,
                  'delta_aic': f.aic - best_aic, 'delta_bic': f.bic - best_bic, 'warnings': len(f.warnings)}
                 for name, f in rows]
        for key, weight in (('delta_aic', 'akaike_weight'), ('delta_bic', 'bic_weight')):
            w = np.exp(-0.5 * np.array([r[key] for r in table]))
            for r, wi in zip(table, w / w.sum(), strict=True):
                r[weight] = float(wi)
        selected = table[0]['model']
        tied = [r for r in table if r['delta_aic'] <= AIC_TIE]
        by_aic = min(tied, key=lambda r: (r['n_params'], r['delta_aic']))['model']
        second = table[1]['delta_bic'] if len(table) > 1 else math.inf
        # Kass & Raftery's scale for Bayes factors, 2 ln B ~ delta BIC
        strength = ('decisively' if second > 10 else 'strongly' if second > 6 else 'positively' if second > 2
                    else 'only weakly')
        if by_aic == selected:
            aic_text = 'AIC agrees'
        else:
            sel, alt = (next(r for r in table if r['model'] == m) for m in (selected, by_aic))
            aic_text = f'AIC prefers {by_aic} by {sel["delta_aic"] - alt["delta_aic"]:.1f} units' + (
                f' (see whether the parameters {by_aic} adds are consistent with zero)'
                if alt['n_params'] > sel['n_params'] else '')
        verdict_text = (f'{_label(temp)}: the data support {selected} {strength} '
                        f'(next best delta BIC {second:.1f}); {aic_text}')
        out.append({'temperature': temp, 'ranking': table, 'selected': selected, 'selected_bic': selected,
                    'selected_aic': by_aic, 'verdict': verdict_text})
    return out


def _label(temp):
    return 'unknown temperature' if temp is None else f'{temp:g} degC'
