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

"""Exponential relaxation modes: exact discretisation and sum-of-exponentials (Prony) fits.

A linear viscoelastic element with static stiffness K_e is represented as a generalised Maxwell
model (a sum of exponentials in the relaxation function)::

    K(s) ~= K_e + sum_i g_i * s u_i / (1 + s u_i)        g_i >= 0, u_i > 0 [s]
    F(t)  = K_e x(t) + sum_i g_i (x(t) - z_i(t)),          u_i dz_i/dt = x - z_i

Each mode z_i is discretised *exactly* for an input that is piecewise linear between samples
(first-order hold), which is what a rig sampling at period h sees::

    a = exp(-h/u),  b0 = 1 - u (1 - a)/h,  b1 = (1 - a) - b0
    z[n] = a z[n-1] + b0 x[n] + b1 x[n-1]

so fast modes (u << h) become an instantaneous spring and slow modes the trapezoidal rule, both
unconditionally stable. The steady-state response of the discrete model to a sampled sine is the
exact continuous response to its piecewise-linear interpolant; relative to the continuous K(jw)
this loses at most about (w h)^2 / 12 of the loss stiffness (0.82 % at 50 Hz and 1 kHz, 0.033 %
at 5 kHz) and far less of the storage stiffness (see :func:`discrete_response`).
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import nnls
from scipy.signal import lfilter


def foh_coefficients(u, h: float):
    """Exact first-order-hold coefficients (a, b0, b1) of modes with time constants ``u`` [s] at step ``h`` [s]."""
    u = np.asarray(u, dtype=float)
    r = h / u
    a = np.exp(-r)
    one_minus_a = -np.expm1(-r)
    b0 = 1.0 - one_minus_a / r
    b1 = one_minus_a - b0
    return a, b0, b1


def relaxation_times(h: float, f_lo: float, f_hi: float, anchor: float, per_decade: float = 3.0):
    """Log-spaced relaxation times [s] covering [1/(2 pi f_hi)/10, 10/(2 pi f_lo)], on a grid through ``anchor``.

    Anchoring the grid on the element's own relaxation time keeps nearly-integer orders
    (alpha -> 1, where the relaxation spectrum collapses onto tau) exact.
    """
    u_lo = 1.0 / (2 * np.pi * f_hi) / 10.0
    u_hi = 10.0 / (2 * np.pi * f_lo)
    d = 1.0 / per_decade
    k_lo = np.floor(np.log10(u_lo / anchor) / d)
    k_hi = np.ceil(np.log10(u_hi / anchor) / d)
    return anchor * 10.0 ** (d * np.arange(k_lo, k_hi + 1))


def fit_modes(kfun, k_static: float, u, f_lo: float, f_hi: float, n_freq: int = 400):
    """Non-negative least-squares weights g_i [N/m] so that K_e + sum g_i jwu_i/(1+jwu_i) matches ``kfun``.

    kfun(omega) -> complex stiffness [N/m] at circular frequencies omega [rad/s]. The residuals of the
    real and imaginary parts are each scaled by the target's own real and imaginary part, so the fit
    minimises the *relative* storage and loss errors over log-spaced frequencies in [f_lo, f_hi] [Hz].
    Non-negative weights make the model passive and its recursion stable.
    Returns (g, max_rel_storage_error, max_rel_loss_error) on the fitting grid.
    """
    u = np.asarray(u, dtype=float)
    w = 2 * np.pi * np.logspace(np.log10(f_lo), np.log10(f_hi), n_freq)
    target = np.asarray(kfun(w), dtype=complex)
    s = 1j * w[:, None] * u[None, :]
    basis = s / (1.0 + s)
    re, im = target.real, target.imag
    a = np.vstack([basis.real / re[:, None], basis.imag / im[:, None]])
    b = np.concatenate([(re - k_static) / re, im / im])
    g, _ = nnls(a, b, maxiter=50 * len(u) + 1000)
    fit = k_static + basis @ g
    return g, float(np.max(np.abs(fit.real / re - 1))), float(np.max(np.abs(fit.imag / im - 1)))


def discrete_response(k_static: float, g, u, h: float, frequency):
    """Steady-state complex stiffness [N/m] of the discretised mode bank at ``frequency`` [Hz] (exact, z-domain)."""
    a, b0, b1 = foh_coefficients(u, h)
    q = np.exp(-2j * np.pi * np.asarray(frequency, dtype=float) * h)[..., None]
    hz = (b0 + b1 * q) / (1.0 - a * q)
    return k_static + ((1.0 - hz) * np.asarray(g)).sum(-1)


class ModeBank:
    """Streaming/batch evaluation of sum_i g_i (x - z_i) for FOH-discretised modes (the viscous force [N])."""

    SHORT_RUN = 32      # [samples] up to this many, run() recurses in plain floats instead of an lfilter per mode

    def __init__(self, g, u, h: float):
        self.g = np.ascontiguousarray(g, dtype=float)
        self.u = np.ascontiguousarray(u, dtype=float)
        self.h = float(h)
        self.a, self.b0, self.b1 = foh_coefficients(self.u, self.h)
        self.g_sum = float(self.g.sum())
        m = self.g.size
        # streaming: one mat-vec per sample on s = [z_1..z_M, x[n], x[n-1]] (fewer numpy calls)
        self._mat = np.zeros((m, m + 2))
        self._mat[:, :m] = np.diag(self.a)
        self._mat[:, m] = self.b0
        self._mat[:, m + 1] = self.b1
        self._s = np.zeros(m + 2)
        # run() of a short batch (_run_short): lfilter's coefficients of each mode's filter of g z
        self._b0g, self._b1g, self._a1 = (self.g * self.b0).tolist(), (self.g * self.b1).tolist(), (-self.a).tolist()
        self.reset()

    @property
    def z(self) -> np.ndarray:
        return self._s[:self.g.size]

    @z.setter
    def z(self, value):
        self._s[:self.g.size] = value

    @property
    def x_prev(self) -> float:
        return float(self._s[-1])

    @x_prev.setter
    def x_prev(self, value):
        self._s[-1] = value

    def reset(self, x0: float = 0.0):
        """Relaxed state at displacement x0 [m] (all modes in equilibrium)."""
        self._s[:] = float(x0)

    def get_state(self):
        return (self.z.copy(), self.x_prev)

    def set_state(self, state):
        self.z = np.array(state[0], dtype=float)
        self.x_prev = float(state[1])

    def step(self, x: float) -> float:
        s = self._s
        s[-2] = x
        z = self._mat @ s
        s[:-2] = z
        s[-1] = x
        return self.g_sum * x - float(self.g.dot(z))

    def run(self, x: np.ndarray, out: np.ndarray = None) -> np.ndarray:
        """Viscous force [N] for displacements ``x`` [m] (shape (n,)), continuing from the current state.

        ``out``: optional array of shape (n,) to write the result into.
        """
        x = np.asarray(x, dtype=float)
        if out is None:
            out = np.empty_like(x)
        if x.size == 0:
            return out
        np.multiply(x, self.g_sum, out=out)
        if x.size <= self.SHORT_RUN:
            return self._run_short(x, out)
        z_last = np.empty(self.g.size)
        x_prev = self.x_prev
        for i in range(self.g.size):
            g, a, b0, b1 = self.g[i], self.a[i], self.b0[i], self.b1[i]
            # filter g*z directly (saves a multiply per sample); zi is the transposed-direct-form-II
            # state that reproduces z[n-1] and x[n-1] of the recursion
            zi = [g * (a * self.z[i] + b1 * x_prev)]
            gz, _ = lfilter([g * b0, g * b1], [1.0, -a], x, zi=zi)
            out -= gz
            z_last[i] = gz[-1] / g
        self.z = z_last
        self.x_prev = float(x[-1])
        return out

    def _run_short(self, x: np.ndarray, out: np.ndarray) -> np.ndarray:
        """run() for a few samples (a batch of the online model): each mode's recursion in plain floats with the
        very operations lfilter does per sample (transposed direct form II: y = z + b0 x, z = x b1 - y a1), so
        the result is the same to the bit; for a few samples an lfilter call per mode costs far more than its
        arithmetic. ``out`` holds g_sum x on entry.
        """
        xs, forces = x.tolist(), out.tolist()
        state = (self.g * (self.a * self.z + self.b1 * self.x_prev)).tolist()     # lfilter's zi of each mode
        samples, last = range(len(xs)), []
        for z, b0, b1, a1 in zip(state, self._b0g, self._b1g, self._a1, strict=True):
            for k in samples:    # mode by mode, each sample's force less g z in run()'s order of subtraction
                xk = xs[k]
                y = z + b0 * xk
                z = xk * b1 - y * a1
                forces[k] -= y
            last.append(y)
        out[:] = forces
        self.z = np.array(last) / self.g
        self.x_prev = xs[-1]
        return out
