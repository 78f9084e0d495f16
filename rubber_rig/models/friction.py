"""Friction elements: Berg's smooth friction (seed 000 Eq. 16-22) and smooth Coulomb (seed 002).

Berg's element remembers a reference state (x_s, F_fs); following seed 000 Section 5.2 it is
updated to the previous sample's displacement and friction force whenever the sign of the
displacement increment changes (a zero increment keeps the last direction). Between reversals the
force is the closed form of Eq. 16, which is what makes the batch path vectorised: only the
reference states at the reversals are computed sequentially.
"""
from __future__ import annotations

import math

import numpy as np


def berg_force(x, x_s, f_s, f_fmax: float, x2: float):
    """Berg friction force [N] (seed 000 Eq. 16) for displacement ``x`` [m] and reference (x_s [m], f_s [N]).

    Broadcasts over arrays; identical arithmetic for scalars and arrays so streaming and batch agree.
    """
    d = np.subtract(x, x_s)
    mu = np.divide(f_s, f_fmax)
    up = d > 0
    # Eq. 16 both branches at once: F = F_fs + d A / (B + |d|), no division by zero at d = 0
    a = np.where(up, f_fmax - f_s, f_fmax + f_s)
    b = np.where(up, x2 * (1.0 - mu), x2 * (1.0 + mu))
    return f_s + d * a / (b + np.abs(d))


def _berg_scalar(x, x_s, f_s, f_fmax, x2):
    d = x - x_s
    mu = f_s / f_fmax
    if d > 0:
        return f_s + d * (f_fmax - f_s) / (x2 * (1.0 - mu) + d)
    return f_s + d * (f_fmax + f_s) / (x2 * (1.0 + mu) - d)


def berg_steady_state(amplitude, f_fmax: float, x2: float):
    """Steady-state Berg properties for x = x0 sin(wt) (seed 000 Eq. 17-22).

    Returns dict of arrays: f_f0 [N] force amplitude (Eq. 17), energy [J] per cycle (Eq. 18),
    k_df [N/m] (Eq. 19), d_f [-] (Eq. 20), k_fs, k_fl [N/m] (Eq. 21, 22).
    """
    x0 = np.asarray(amplitude, dtype=float)
    f0 = f_fmax / (2 * x2) * (np.sqrt(x2 ** 2 + x0 ** 2 + 6 * x2 * x0) - x2 - x0)
    mu0 = f0 / f_fmax
    xa = x2 * (1 + mu0)
    energy = 2 * f_fmax * (2 * x0 - xa * (1 + mu0) * np.log((xa + 2 * x0) / xa))
    k_df = f0 / x0
    d_f = energy / (np.pi * f0 * x0)
    return {'f_f0': f0, 'energy': energy, 'k_df': k_df, 'd_f': d_f,
            'k_fs': k_df * np.sqrt(1 - d_f ** 2), 'k_fl': k_df * d_f}


class BergFriction:
    """Berg's smooth friction element (2 parameters: f_fmax [N], x2 [m]); branch 'friction'."""
    branch_names = ('friction',)
    kinds = ('friction',)

    def __init__(self, f_fmax: float, x2: float, dt: float):
        self.f_fmax, self.x2, self.dt = float(f_fmax), float(x2), float(dt)
        self.reset()

    def reset(self, x0: float = 0.0):
        """Virgin state at x0 [m]: reference (x0, 0), no direction yet."""
        self.x_prev, self.direction, self.x_s, self.f_s, self.f_prev = float(x0), 0, float(x0), 0.0, 0.0

    def get_state(self):
        return (self.x_prev, self.direction, self.x_s, self.f_s, self.f_prev)

    def set_state(self, state):
        self.x_prev, self.direction, self.x_s, self.f_s, self.f_prev = state
        self.direction = int(self.direction)

    def step(self, x: float):
        d = x - self.x_prev
        direction = 1 if d > 0 else (-1 if d < 0 else self.direction)
        if direction != self.direction and self.direction != 0:
            self.x_s, self.f_s = self.x_prev, self.f_prev   # reversal: previous sample becomes reference
        self.direction = direction
        f = _berg_scalar(x, self.x_s, self.f_s, self.f_fmax, self.x2)
        self.x_prev, self.f_prev = x, f
        return (f,)

    def run(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        n = x.size
        if n == 0:
            return np.zeros((1, 0))
        xp = np.empty(n + 1)
        xp[0] = self.x_prev
        xp[1:] = x
        direction = np.sign(np.diff(xp))
        if not direction.all():
            # zero increments keep the last non-zero direction (initially the stored one)
            idx = np.where(direction != 0, np.arange(n), -1)
            np.maximum.accumulate(idx, out=idx)
            direction = np.where(idx >= 0, direction[np.maximum(idx, 0)], float(self.direction))
        rev = np.flatnonzero(direction[1:] != direction[:-1]) + 1
        if self.direction != 0 and direction[0] != self.direction:
            rev = np.concatenate(([0], rev))
        # reference state per segment: sequential only over the reversals
        fm, x2 = self.f_fmax, self.x2
        xs, fs, f_prev = self.x_s, self.f_s, self.f_prev
        xs_seg, fs_seg = [xs], [fs]
        xl = xp[rev].tolist()
        for k, i in enumerate(rev.tolist()):
            if i > 0:
                f_prev = _berg_scalar(xl[k], xs, fs, fm, x2)
            xs, fs = xl[k], f_prev
            xs_seg.append(xs)
            fs_seg.append(fs)
        bounds = np.concatenate(([0], rev, [n]))
        counts = np.diff(bounds)
        xs_a, fs_a = np.array(xs_seg), np.array(fs_seg)
        if counts[0] == 0:   # reversal at the first sample: the stored reference has no samples
            xs_a, fs_a, counts, bounds = xs_a[1:], fs_a[1:], counts[1:], bounds[1:]
        seg_dir = direction[bounds[:-1]]
        # Eq. 16 in one expression: F = F_fs + d A / (B + |d|), A and B per segment and direction
        mu = fs_a / fm
        a_coef = np.where(seg_dir > 0, fm - fs_a, fm + fs_a)
        b_coef = np.where(seg_dir > 0, x2 * (1.0 - mu), x2 * (1.0 + mu))
        d = x - np.repeat(xs_a, counts)
        f = np.repeat(fs_a, counts) + d * np.repeat(a_coef, counts) / (np.repeat(b_coef, counts) + np.abs(d))
        self.x_prev, self.direction = float(x[-1]), int(direction[-1])
        self.x_s, self.f_s, self.f_prev = xs, fs, float(f[-1])
        return f[None, :]

    def complex_stiffness(self, frequency, amplitude):
        """Equivalent complex stiffness K_fs + j K_fl [N/m] (seed 000 Eq. 21-22), shape (1, ...)."""
        ss = berg_steady_state(amplitude, self.f_fmax, self.x2)
        return np.asarray(ss['k_fs'] + 1j * ss['k_fl'] + 0 * np.asarray(frequency, dtype=float))[None]


class SmoothCoulomb:
    """Smooth Coulomb friction F = F_c tanh(a v) (seed 002 Eq. 46); v from the backward difference.

    f_c [N] friction force level, a [s/m] steepness. Branch 'friction'.
    """
    branch_names = ('friction',)
    kinds = ('friction',)

    def __init__(self, f_c: float, a: float, dt: float):
        self.f_c, self.a, self.dt = float(f_c), float(a), float(dt)
        self.reset()

    def reset(self, x0: float = 0.0):
        self.x_prev = float(x0)

    def get_state(self):
        return (self.x_prev,)

    def set_state(self, state):
        self.x_prev = float(state[0])

    def step(self, x: float):
        v = (x - self.x_prev) / self.dt
        self.x_prev = x
        return (self.f_c * math.tanh(self.a * v),)

    def run(self, x):
        x = np.asarray(x, dtype=float)
        if x.size == 0:
            return np.zeros((1, 0))
        v = np.diff(np.concatenate(([self.x_prev], x))) / self.dt
        self.x_prev = float(x[-1])
        return (self.f_c * np.tanh(self.a * v))[None, :]

    def complex_stiffness(self, frequency, amplitude, n_quad: int = 512):
        """First-harmonic (describing-function) stiffness [N/m] of the continuous element, by quadrature.

        For x = x0 sin(wt), F = F_c tanh(a w x0 cos(wt)) is in phase with velocity: purely loss,
        K_l = (1/(pi x0)) * int_0^{2 pi} F cos(theta) d theta.
        """
        f, x0 = np.broadcast_arrays(np.asarray(frequency, float), np.asarray(amplitude, float))
        th = (np.arange(n_quad) + 0.5) * 2 * np.pi / n_quad
        vel = 2 * np.pi * f[..., None] * x0[..., None] * np.cos(th)
        k_l = (self.f_c * np.tanh(self.a * vel) * np.cos(th)).mean(-1) * 2 / x0
        return np.asarray(1j * k_l)[None]
