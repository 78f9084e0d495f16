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
Butterworth, forward-backward, cut-off 8x the highest block frequency) and with the remaining
noise-sized reversals flattened (`clean_reversals`): raw transducer noise makes Berg's element see
spurious velocity reversals and reset its reference state, which biases x2 and F_fmax by tens of
per cent (0.5 um noise on a 1 mm sine, 1 kHz); low-pass alone still leaves micro-reversals at the
turning points. Even so, the time-domain fit is the more fragile one: its x2-F_fmax valley is
flat (the initial friction slope F_fmax/x2 is what the loops pin down), so input errors of 1e-4 of
the amplitude move x2 and F_fmax together by a few per cent.
"""
from __future__ import annotations

import time

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import butter, sosfiltfilt

from .identify import PARAM_NAMES, FitResult, _z_bounds, jacobian_uncertainty, params_to_z, z_to_params


def simulate(params: dict, x, dt):
    """Force [N] of the seed-000 model (rubber_rig.models, default scheme) for displacement x [m]."""
    from rubber_rig.models import Seed000Params, build_model
    model = build_model(Seed000Params(**{k: float(params[k]) for k in PARAM_NAMES}), dt)
    out = model.run(np.asarray(x, float))
    return np.asarray(out[0] if isinstance(out, tuple) else out, float)


def turning_points(x, h):
    """Indices of the alternating extrema of x that stand out by more than h (zig-zag filter)."""
    x = np.asarray(x, float)
    idx = [0]
    imax = imin = ext = 0
    direction = 0                  # +1 rising, -1 falling, 0 not yet known
    for i in range(1, x.size):
        xi = x[i]
        if direction == 0:
            if xi > x[imax]:
                imax = i
            if xi < x[imin]:
                imin = i
            if x[imax] - xi > h:
                idx.append(imax)
                direction, ext = -1, i
            elif xi - x[imin] > h:
                idx.append(imin)
                direction, ext = 1, i
        elif direction > 0:
            if xi > x[ext]:
                ext = i
            elif x[ext] - xi > h:
                idx.append(ext)
                direction, ext = -1, i
        else:
            if xi < x[ext]:
                ext = i
            elif xi - x[ext] > h:
                idx.append(ext)
                direction, ext = 1, i
    idx.append(x.size - 1)
    return np.unique(np.asarray(idx, int))


def clean_reversals(x, h):
    """x made monotone between its real turning points (those standing out by more than h).

    Berg's element resets its reference state at every velocity reversal; noise-sized wiggles
    (< h) are not reversals of the specimen, so they are flattened (running max / min), which
    leaves the rate-independent friction loop untouched.
    """
    y = np.array(x, float)
    tp = turning_points(y, h)
    for a, b in zip(tp[:-1], tp[1:]):
        seg = y[a:b + 1]
        y[a:b + 1] = np.maximum.accumulate(seg) if seg[-1] >= seg[0] else np.minimum.accumulate(seg)
    return y


def smooth_displacement(x, dt, f_max):
    """Measured displacement as the model input: zero-phase low-pass, then noise reversals removed."""
    from .blocks import _noise_level
    x = np.asarray(x, float)
    fs = 1.0 / dt
    fc = min(8.0 * f_max, 0.4 * fs)
    y = x
    if 0 < fc < 0.5 * fs and x.size > 30:
        y = sosfiltfilt(butter(4, fc, fs=fs, output='sos'), x)
    h = max(5.0 * _noise_level(x), 2e-4 * float(np.max(np.abs(x - np.median(x))) or 1.0))
    return clean_reversals(y, h)


class TimeDomainProblem:
    """Residuals of the force over the analysed cycles of every block of several runs."""

    def __init__(self, runs_blocks, points_per_block=200):
        """runs_blocks: list of (RunData, [BlockResult]) sharing one specimen state (temperature)."""
        self.items = []
        for run, blocks in runs_blocks:
            if not blocks:
                continue
            end = min(max(b.stop for b in blocks) + 1, run.displacement.size)
            f_max = max(b.frequency for b in blocks)
            x = smooth_displacement(run.displacement[:end], run.dt, f_max)
            windows = []
            for b in blocks:
                n = b.stop - b.start
                step = max(1, n // points_per_block)
                idx = np.arange(b.start, b.stop, step)
                scale = 1.0 / (b.k_dyn * b.amplitude * np.sqrt(idx.size))
                windows.append((idx, scale))
            self.items.append((run, x, run.force[:end], windows))

    def predict(self, params):
        return [simulate(params, x, run.dt) for run, x, _, _ in self.items]

    def residuals_from(self, predictions):
        out = []
        for (run, x, force, windows), pred in zip(self.items, predictions):
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
