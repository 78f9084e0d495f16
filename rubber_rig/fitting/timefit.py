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

"""Time-domain identification: force predicted from the measured displacement, fitted to the loops.

K_dyn and C_eq condense each steady loop into two numbers; the loop's shape (the sharp friction
corners of seed 000 Fig. 5/6) carries more, which separates Berg's x2 from F_fmax and the viscous
from the frictional damping. Here the model of `rubber_rig.models` runs over the whole recording
(so its fractional memory and friction reference state see the same history as the specimen did),
and the residual is the force error in the analysed (steady, post-settling) cycles of every block:

    r = (F_model - F_measured - offset_block) / (F_amplitude_block * sqrt(n_block))

so every block weighs the same whatever its length and force level (like the relative errors of
Eq. 28), and a per-block force offset (load-cell zero, preload) is removed analytically. Each block
contributes at most `points_per_block` evenly spaced samples.

The displacement fed to the model is the measured one after a zero-phase low-pass (4th-order
Butterworth, forward-backward, cut-off 8x the highest block frequency), and the model runs with
Berg's reversal deadband (`model_input`: 5x the displacement noise level, at least 2e-4 of the
amplitude): raw transducer noise makes Berg's element see spurious velocity reversals and reset its
reference state, which biases x2 and F_fmax by tens of per cent (0.5 um noise on a 1 mm sine,
1 kHz); low-pass alone still leaves micro-reversals at the turning points. (Until the model had the
deadband, those were flattened here in the input, with the same threshold; the fitted parameters
agree with that to ~1e-4 relative.) Even so, the time-domain fit is the more fragile one: its
x2-F_fmax valley is flat (the initial friction slope F_fmax/x2 is what the loops pin down), so input
errors of 1e-4 of the amplitude move x2 and F_fmax together by a few per cent.
"""
from __future__ import annotations

import time

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import butter, sosfiltfilt

from rubber_rig.models import ZenerBergParams, build_model

from .blocks import noise_level
from .identify import PARAM_NAMES, FitResult, _z_bounds, jacobian_uncertainty, params_to_z, z_to_params


def simulate(params: dict, x, dt, reversal_threshold: float = 0.0):
    """Force [N] of the seed-000 model (rubber_rig.models, default scheme) for displacement x [m];
    ``reversal_threshold`` [m] is Berg's reversal deadband (rubber_rig.models.friction), 0 = the paper's rule.
    """
    model = build_model(ZenerBergParams(**{k: float(params[k]) for k in PARAM_NAMES}), dt,
                        friction_reversal_threshold=reversal_threshold)
    return np.asarray(model.run(np.asarray(x, float)), float)


def model_input(x, dt, f_max):
    """(displacement [m], reversal threshold [m]) to run the model on for a measured displacement ``x``:
    zero-phase low-pass, and Berg's reversal deadband at the noise-sized reversals of x (5x its noise
    level, at least 2e-4 of its amplitude).
    """
    x = np.asarray(x, float)
    fs = 1.0 / dt
    fc = min(8.0 * f_max, 0.4 * fs)
    y = x
    if 0 < fc < 0.5 * fs and x.size > 30:
        y = sosfiltfilt(butter(4, fc, fs=fs, output='sos'), x)
    h = max(5.0 * noise_level(x), 2e-4 * float(np.max(np.abs(x - np.median(x))) or 1.0))
    return y, h


def run_input(run, blocks, until: int = 0):
    """(end, x, h): the model input (`model_input`, at the blocks' highest frequency) for the measured
    displacement of ``run`` (RunData) up to the closing sample of the last of its ``blocks`` (or to
    sample ``until`` if that is later), i.e. samples [0, end).
    """
    end = min(max(max(b.stop for b in blocks) + 1, until), run.displacement.size)
    x, h = model_input(run.displacement[:end], run.dt, max(b.frequency for b in blocks))
    return end, x, h


def model_force(params: dict, run, blocks):
    """(end, force [N] over samples [0, end)): the model with ``params`` run over the measured
    displacement of ``run`` as `run_input` prepares it.
    """
    end, x, h = run_input(run, blocks)
    return end, simulate(params, x, run.dt, h)


class TimeDomainProblem:
    """Residuals of the force over the analysed cycles of every block of several runs."""

    def __init__(self, runs_blocks, points_per_block=200):
        """runs_blocks: list of (RunData, [BlockResult]) sharing one specimen state (temperature)."""
        self.items = []
        for run, blocks in runs_blocks:
            if not blocks:
                continue
            end, x, h = run_input(run, blocks)
            windows = []
            for b in blocks:
                n = b.stop - b.start
                step = max(1, n // points_per_block)
                idx = np.arange(b.start, b.stop, step)
                scale = 1.0 / (b.k_dyn * b.amplitude * np.sqrt(idx.size))
                windows.append((idx, scale))
            self.items.append((run, x, h, run.force[:end], windows))

    def predict(self, params):
        return [simulate(params, x, run.dt, h) for run, x, h, _, _ in self.items]

    def residuals_from(self, predictions):
        out = []
        for (_, _, _, force, windows), pred in zip(self.items, predictions, strict=False):
            for idx, scale in windows:
                e = pred[idx] - force[idx]
                out.append((e - e.mean()) * scale)
        return np.concatenate(out)

    def residuals(self, params):
        return self.residuals_from(self.predict(params))


def fit_time_domain(problem: TimeDomainProblem, start: dict, bounds: dict, max_nfev=60,
                    progress=None) -> FitResult:
    """Least squares on the time-domain residuals from `start` (the harmonic fit), within `bounds`."""
    lo, hi = _z_bounds(bounds)
    z0 = np.clip(params_to_z(start), lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
    # a refinement, not a new search: stay within ~35 % (alpha: +-0.15) of the harmonic estimate,
    # where the loop residual is smooth (far away, friction reversals make it rugged)
    span = np.array([0.3, 0.3, 0.3, 0.15, 0.3, 0.3])
    lo, hi = np.maximum(lo, z0 - span), np.minimum(hi, z0 + span)
    count = {'n': 0}

    def fun(z):
        count['n'] += 1
        if progress is not None:
            progress(min(count['n'] / (max_nfev * 7.0), 0.99), 'time-domain fit')
        p = {k: float(v) for k, v in z_to_params(z).items()}
        return problem.residuals(p)

    t0 = time.perf_counter()
    ls = least_squares(fun, z0, bounds=(lo, hi), method='trf', x_scale=1.0, diff_step=1e-4,
                       xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=max_nfev)
    t1 = time.perf_counter()
    p = {k: float(v) for k, v in z_to_params(ls.x).items()}
    unc = jacobian_uncertainty(problem.residuals, p, eps=1e-3)
    t2 = time.perf_counter()
    res = FitResult(params=p, method='time', objective=float(np.sum(ls.fun ** 2)), bounds=bounds,
                    uncertainty=unc, timings={'time_fit_s': t1 - t0, 'uncertainty_s': t2 - t1},
                    stages={'time': dict(p)})
    res.timings['model_runs'] = count['n']
    if ls.status == 0:
        res.messages.append(f'time-domain fit stopped after {max_nfev} evaluations (not converged)')
    return res
