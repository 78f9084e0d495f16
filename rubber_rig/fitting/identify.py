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

"""Identification of the seed-000 six-parameter model from measured block properties (Eq. 28-29).

Objective (seed 000 Eq. 29): F(p) = sum over blocks of w_K e_K^2 + w_C e_C^2 with the relative errors
e_K = (K_dyn^s - K_dyn^m) / K_dyn^m and e_C = (C_eq^s - C_eq^m) / C_eq^m (Eq. 28). The model side is
evaluated the way the rig measures (first-harmonic K_dyn, loop-area energy; see `properties`).

Search space (all positive scale parameters on a log scale, K_inf written as K0 + dK so that
K_inf >= K0 always holds). Bounds are derived from the data so that they scale with the specimen:
    K0      in [0.05, 1.0] x min measured K_dyn      (K_dyn >= storage >= K0 plus friction)
    dK      in [1e-4, 20]  x max measured K_dyn
    tau     in [0.01 / (2 pi f_max), 100 / (2 pi f_min)]   (relaxation within reach of the data)
    alpha   in [0.05, 1]
    x2      in [0.01, 50]  x max amplitude
    F_fmax  in [0.001, 5]  x max measured force amplitude
Global stage: scipy differential_evolution (the counterpart of the paper's genetic algorithm),
vectorised over the population. Local stage: scipy least_squares (trust-region reflective) on the
same residual vector. Uncertainty: from the Jacobian J of the residuals with respect to ln(p) at the
optimum, cov = s^2 (J^T J)^-1 with s^2 = sum r^2 / (m - n); reported as relative 1-sigma per
parameter, with the correlation matrix and a sensitivity (|dF/d ln p| column norms of J).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import differential_evolution, least_squares

from .properties import measured_style_properties

PARAM_NAMES = ('k0', 'k_inf', 'tau', 'alpha', 'x2', 'f_fmax')
PARAM_UNITS = {'k0': 'N/m', 'k_inf': 'N/m', 'tau': 's', 'alpha': '-', 'x2': 'm', 'f_fmax': 'N'}
_Z_NAMES = ('ln_k0', 'ln_dk', 'ln_tau', 'alpha', 'ln_x2', 'ln_f_fmax')


def z_to_params(z):
    """Optimiser coordinates -> physical parameters (arrays broadcast along trailing axes)."""
    z = np.asarray(z, float)
    k0 = np.exp(z[0])
    return {'k0': k0, 'k_inf': k0 + np.exp(z[1]), 'tau': np.exp(z[2]), 'alpha': z[3],
            'x2': np.exp(z[4]), 'f_fmax': np.exp(z[5])}


def params_to_z(p):
    return np.array([np.log(p['k0']), np.log(max(p['k_inf'] - p['k0'], 1e-12 * p['k0'])),
                     np.log(p['tau']), p['alpha'], np.log(p['x2']), np.log(p['f_fmax'])])


@dataclass
class Targets:
    """Measured block properties as arrays (SI)."""

    frequency: np.ndarray
    amplitude: np.ndarray
    k_dyn: np.ndarray
    c_eq: np.ndarray

    @classmethod
    def from_blocks(cls, blocks):
        return cls(*(np.array([getattr(b, k) for b in blocks], float)
                     for k in ('frequency', 'amplitude', 'k_dyn', 'c_eq')))

    def __len__(self):
        return self.frequency.size


def data_bounds(t: Targets) -> dict:
    """Documented search bounds (see module docstring) in physical units: name -> (lo, hi)."""
    kmin, kmax = float(t.k_dyn.min()), float(t.k_dyn.max())
    fmin, fmax = float(t.frequency.min()), float(t.frequency.max())
    amax = float(t.amplitude.max())
    force = float(np.max(t.k_dyn * t.amplitude))
    return {'k0': (0.05 * kmin, 1.0 * kmin), 'dk': (1e-4 * kmax, 20.0 * kmax),
            'tau': (0.01 / (2 * np.pi * fmax), 100.0 / (2 * np.pi * fmin)), 'alpha': (0.05, 1.0),
            'x2': (0.01 * amax, 50.0 * amax), 'f_fmax': (1e-3 * force, 5.0 * force)}


def _z_bounds(b):
    lo = np.array([np.log(b['k0'][0]), np.log(b['dk'][0]), np.log(b['tau'][0]), b['alpha'][0],
                   np.log(b['x2'][0]), np.log(b['f_fmax'][0])])
    hi = np.array([np.log(b['k0'][1]), np.log(b['dk'][1]), np.log(b['tau'][1]), b['alpha'][1],
                   np.log(b['x2'][1]), np.log(b['f_fmax'][1])])
    return lo, hi


def harmonic_residuals(z, t: Targets, w_k=100.0, w_c=1.0):
    """Residual vector sqrt(w) * e of Eq. 28; z may be (6,) or (6, S) -> (2B,) or (S, 2B)."""
    z = np.asarray(z, float)
    p = z_to_params(z[..., None] if z.ndim == 2 else z)
    pr = measured_style_properties(p['k0'], p['k_inf'], p['tau'], p['alpha'], p['x2'], p['f_fmax'],
                                   t.frequency, t.amplitude)
    e_k = (pr['k_dyn'] - t.k_dyn) / t.k_dyn
    e_c = (pr['c_eq'] - t.c_eq) / t.c_eq
    return np.concatenate([np.sqrt(w_k) * e_k, np.sqrt(w_c) * e_c], axis=-1)


def objective(z, t, w_k=100.0, w_c=1.0):
    """Seed 000 Eq. 29 (vectorised over a population when z is (6, S))."""
    r = harmonic_residuals(z, t, w_k, w_c)
    out = np.sum(r * r, axis=-1)
    return np.where(np.isfinite(out), out, 1e30)


def jacobian_uncertainty(residual_fn, p: dict, eps=1e-4):
    """Relative 1-sigma uncertainty, correlation and sensitivity of each parameter at the optimum.

    Central differences of the residuals with respect to ln(p) (alpha included: relative steps).
    """
    names = PARAM_NAMES
    base = np.array([p[n] for n in names], float)
    r0 = residual_fn(dict(p))
    cols = []
    for i, n in enumerate(names):
        up = base[i] * np.exp(eps)
        if n == 'alpha':
            up = min(up, 1.0)          # fractional order stays in (0, 1]: one-sided at the bound
        if n == 'k0':
            up = min(up, p['k_inf'])   # K0 <= K_inf
        down = base[i] * np.exp(-eps)
        if n == 'k_inf':
            down = max(down, p['k0'])
        step = base.copy()
        step[i] = up
        rp = residual_fn(dict(zip(names, step, strict=False)))
        step[i] = down
        rm = residual_fn(dict(zip(names, step, strict=False)))
        cols.append((rp - rm) / np.log(up / down))
    jac = np.column_stack(cols)
    m, n = jac.shape
    dof = max(m - n, 1)
    s2 = float(np.sum(r0 * r0)) / dof
    jtj = jac.T @ jac
    try:
        cov = np.linalg.pinv(jtj) * s2
    except np.linalg.LinAlgError:
        cov = np.full((n, n), np.nan)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = cov / np.outer(sd, sd)
    sens = np.linalg.norm(jac, axis=0)
    return {
        'relative_sigma': {n: float(v) for n, v in zip(names, sd, strict=False)},
        'sigma': {n: float(v * p[n]) for n, v in zip(names, sd, strict=False)},
        'sensitivity': {n: float(v) for n, v in zip(names, sens, strict=False)},
        'correlation': [[float(c) for c in row] for row in corr],
        'condition_number': float(np.linalg.cond(jtj)),
        'residual_rms': float(np.sqrt(np.mean(r0 * r0))),
    }


@dataclass
class FitResult:
    params: dict
    method: str
    objective: float
    bounds: dict
    uncertainty: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    stages: dict = field(default_factory=dict)   # parameters after each stage
    messages: list = field(default_factory=list)


def fit_harmonic(t: Targets, w_k=100.0, w_c=1.0, seed=0, maxiter=400, popsize=20,
                 bounds=None, progress=None, workers=1) -> FitResult:
    """Eq. 29 by differential evolution, then least-squares polish. Returns physical parameters."""
    if len(t) < 4:
        raise ValueError(f'{len(t)} usable blocks; the six-parameter model needs at least 4 '
                         '(12 numbers: K_dyn and C_eq per block) spread over frequency and amplitude')
    b = bounds or data_bounds(t)
    lo, hi = _z_bounds(b)
    t0 = time.perf_counter()
    calls = {'n': 0}

    def cb(xk, convergence=0.0):
        calls['n'] += 1
        if progress is not None:
            progress(min(calls['n'] / maxiter, max(convergence, 0.0)), 'global search')
        return False

    de = differential_evolution(objective, list(zip(lo, hi, strict=False)), args=(t, w_k, w_c), seed=seed,
                                maxiter=maxiter, popsize=popsize, tol=1e-10, atol=0,
                                mutation=(0.5, 1.0), recombination=0.9, init='sobol',
                                polish=False, vectorized=True, updating='deferred',
                                workers=workers, callback=cb)
    t1 = time.perf_counter()
    ls = least_squares(harmonic_residuals, de.x, bounds=(lo, hi), args=(t, w_k, w_c),
                       method='trf', x_scale='jac', xtol=1e-12, ftol=1e-12, gtol=1e-12,
                       max_nfev=2000)
    t2 = time.perf_counter()
    p = {k: float(v) for k, v in z_to_params(ls.x).items()}

    def rfun(pp):
        return harmonic_residuals(params_to_z(pp), t, w_k, w_c)

    unc = jacobian_uncertainty(rfun, p)
    res = FitResult(params=p, method='harmonic', objective=float(np.sum(ls.fun ** 2)), bounds=b,
                    uncertainty=unc,
                    timings={'global_s': t1 - t0, 'polish_s': t2 - t1},
                    stages={'global': {k: float(v) for k, v in z_to_params(de.x).items()},
                            'polish': dict(p)})
    at_bound = [n for n, z, low, high in zip(_Z_NAMES, ls.x, lo, hi, strict=True)
                if min(z - low, high - z) < 1e-6 * (high - low)]
    if at_bound:
        res.messages.append(f'parameters at a search bound: {at_bound}; the data do not constrain them')
    return res
