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

"""Elastic and viscoelastic elements.

Every element with memory works at a fixed sample period ``dt`` [s] (the elastic, stateless ones take none);
all offer

* ``step(x) -> tuple`` of branch forces [N] (streaming), ``run(x) -> array (n_branch, n)`` (batch,
  continuing from and updating the same state), ``reset(x0)``, ``get_state()``/``set_state()``;
* ``complex_stiffness(frequency, amplitude) -> array (n_branch, ...)`` [N/m]: the exact continuous
  steady-state (equivalent) complex stiffness of each branch, for the analytic properties.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter, lfiltic

from .fractional import gl_coefficients, two_order_complex_stiffness, zener_complex_stiffness
from .modes import ModeBank, discrete_response, fit_modes, relaxation_times


class _Stateless:
    """Elastic elements: no memory."""

    kinds = ('elastic',)
    branch_names = ('elastic',)

    def reset(self, x0: float = 0.0):
        pass

    def get_state(self):
        return ()

    def set_state(self, state):
        pass

    def step(self, x: float):
        return (self.force(x),)

    def run(self, x):
        return np.asarray(self.force(np.asarray(x, dtype=float)), dtype=float)[None, :]

    def complex_stiffness(self, frequency, amplitude):
        """Peak-based equivalent stiffness (F(x0) - F(-x0)) / (2 x0) [N/m], no loss (seed 003 Eq. 5 convention)."""
        x0 = np.asarray(amplitude, dtype=float)
        k = (self.force(x0) - self.force(-x0)) / (2 * x0) + 0 * np.asarray(frequency, dtype=float)
        return np.asarray(k, dtype=complex)[None]


class LinearSpring(_Stateless):
    """F = k x, k [N/m]."""

    def __init__(self, k: float):
        self.k = float(k)

    def force(self, x):
        return self.k * x


class PolynomialSpring(_Stateless):
    """F = a0 + a1 x + ... + an x^n (seed 003 Eq. 4); coefficients in SI (a_i in N/m^i)."""

    def __init__(self, coefficients):
        self.coefficients = tuple(float(c) for c in coefficients)
        if not self.coefficients:
            raise ValueError('parameter coefficients of the polynomial spring must not be empty')
        self._poly = np.polynomial.Polynomial(self.coefficients)

    @classmethod
    def odd(cls, k_odd):
        """Odd polynomial K1 x + K3 x^3 + K5 x^5 + ... (seed 004 Eq. 5), k_odd = (K1, K3, K5, ...)."""
        c = [0.0] * (2 * len(k_odd))
        for i, k in enumerate(k_odd):
            c[2 * i + 1] = float(k)
        return cls(c)

    def force(self, x):
        if np.ndim(x) == 0:
            xf, acc = float(x), 0.0
            for c in reversed(self.coefficients):   # Horner, same order as Polynomial for scalars
                acc = acc * xf + c
            return acc
        acc = np.zeros_like(x)
        for c in reversed(self.coefficients):
            acc = acc * x + c
        return acc


class TangentSpring(_Stateless):
    """Dzierzek's non-linear elastic force F = (2 k_t d_t / pi) tan(pi x / (2 d_t)) (seed 001 Eq. 6/19).

    k_t [N/m] slope at x = 0, d_t [m] characteristic thickness: the force grows without bound as
    |x| -> d_t, so |x| >= d_t is rejected (ValueError) instead of returning an infinite force.
    """

    def __init__(self, k_t: float, d_t: float):
        self.k_t, self.d_t = float(k_t), float(d_t)

    def force(self, x):
        if np.any(np.abs(x) >= self.d_t):
            raise ValueError(f'displacement {np.max(np.abs(x)):g} m reaches the tangent spring asymptote '
                             f'd_t = {self.d_t:g} m')
        if np.ndim(x) == 0:
            return 2 * self.k_t * self.d_t / math.pi * math.tan(math.pi * x / (2 * self.d_t))
        return 2 * self.k_t * self.d_t / math.pi * np.tan(math.pi * x / (2 * self.d_t))


class VelocityElement:
    """Base of elements whose force depends on the velocity alone, v[n] = (x[n] - x[n-1]) / dt (backward
    difference); the state is the previous displacement. Subclasses define ``force_of_velocity(v)`` for
    scalars and arrays alike, so streaming and batch run the same arithmetic.
    """

    def __init__(self, dt: float):
        self.dt = float(dt)
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
        return (self.force_of_velocity(v),)

    def run(self, x):
        x = np.asarray(x, dtype=float)
        if x.size == 0:
            return np.zeros((1, 0))
        v = np.diff(np.concatenate(([self.x_prev], x))) / self.dt
        self.x_prev = float(x[-1])
        return np.asarray(self.force_of_velocity(v))[None, :]


class Dashpot(VelocityElement):
    """Kelvin-Voigt dashpot F = c v, c [N s/m]; v = (x[n] - x[n-1]) / dt (backward difference). Branch 'viscous'."""

    kinds = ('viscous',)
    branch_names = ('viscous',)

    def __init__(self, c: float, dt: float):
        self.c = float(c)
        super().__init__(dt)

    def force_of_velocity(self, v):
        return self.c * v

    def complex_stiffness(self, frequency, amplitude):
        w = 2 * np.pi * np.asarray(frequency, dtype=float) + 0 * np.asarray(amplitude, dtype=float)
        return np.asarray(1j * w * self.c)[None]


class _ModeElement:
    """Linear element K_e x + sum of FOH-discretised relaxation modes; branches ('elastic', 'viscous')."""

    kinds = ('elastic', 'viscous')
    branch_names = ('elastic', 'viscous')

    def _init_modes(self, k_static, g, u, dt):
        self.k_static, self.dt = float(k_static), float(dt)
        self.bank = ModeBank(g, u, dt)

    def reset(self, x0: float = 0.0):
        self.bank.reset(x0)

    def get_state(self):
        return self.bank.get_state()

    def set_state(self, state):
        self.bank.set_state(state)

    def step(self, x: float):
        return (self.k_static * x, self.bank.step(x))

    def run(self, x):
        x = np.asarray(x, dtype=float)
        out = np.empty((2, x.size))
        np.multiply(x, self.k_static, out=out[0])
        self.bank.run(x, out=out[1])
        return out

    def discrete_complex_stiffness(self, frequency):
        """Exact steady-state complex stiffness [N/m] of the discrete-time scheme at ``frequency`` [Hz]."""
        return discrete_response(self.k_static, self.bank.g, self.bank.u, self.dt, frequency)

    def _split(self, k_total, amplitude):
        k_total = k_total + 0 * np.asarray(amplitude, dtype=float)
        return np.stack([np.full(k_total.shape, self.k_static, dtype=complex), k_total - self.k_static])


class Maxwell(_ModeElement):
    """Maxwell branch: spring k [N/m] in series with dashpot c [N s/m] (relaxation time c/k). Branch 'viscous'."""

    kinds = ('viscous',)
    branch_names = ('viscous',)

    def __init__(self, k: float, c: float, dt: float):
        self.k, self.c = float(k), float(c)
        self._init_modes(0.0, [self.k], [self.c / self.k], dt)

    def step(self, x: float):
        return (self.bank.step(x),)

    def run(self, x):
        return self.bank.run(np.asarray(x, dtype=float))[None, :]

    def complex_stiffness(self, frequency, amplitude):
        s = 2j * np.pi * np.asarray(frequency, dtype=float) * (self.c / self.k)
        return np.asarray(self.k * s / (1 + s) + 0 * np.asarray(amplitude, dtype=float))[None]


class FractionalZener(_ModeElement):
    """Fractional-derivative Zener model (seed 000 Eq. 4), sum-of-exponentials scheme (see :mod:`.fractional`).

    Branches: 'elastic' = K0 x, 'viscous' = F_ev - K0 x (Eq. 10). ``alpha = 1`` is the ordinary
    Zener model, represented exactly by one mode (K_inf - K0, tau).
    """

    ALPHA_MIN = 0.1   # the scheme's stated error bound holds for ALPHA_MIN <= alpha <= 1 (fractional.py)

    def __init__(self, k0, k_inf, tau, alpha, dt, f_lo=1e-2, f_hi=None, per_decade=2.0):
        self.k0, self.k_inf, self.tau, self.alpha = float(k0), float(k_inf), float(tau), float(alpha)
        if not self.ALPHA_MIN <= self.alpha <= 1.0:
            # measured: at alpha 0.05 the loss error is 1.5 %, at 0.01 the storage error 5 %, beyond the bound
            raise ValueError(f'fractional_zener alpha {self.alpha:g} outside {self.ALPHA_MIN:g}..1, the range in '
                             'which the time-domain scheme keeps its stated accuracy (storage 0.15 %, loss 0.9 % '
                             'at 1 kHz); an order this small is nearly a spring: model it as one')
        f_hi = 0.5 / dt if f_hi is None else float(f_hi)
        if self.k_inf == self.k0:
            u, g, self.fit_error = np.zeros(0), np.zeros(0), (0.0, 0.0)
        elif self.alpha >= 1.0:
            u, g, self.fit_error = np.array([self.tau]), np.array([self.k_inf - self.k0]), (0.0, 0.0)
        else:
            u = relaxation_times(dt, f_lo, f_hi, self.tau, per_decade)
            g, es, el = fit_modes(self.continuous, self.k0, u, f_lo, f_hi)
            keep = g > 0   # modes NNLS switched off cost time and add nothing
            u, g, self.fit_error = u[keep], g[keep], (es, el)
        self._init_modes(self.k0, g, u, dt)

    def continuous(self, omega):
        return zener_complex_stiffness(omega, self.k0, self.k_inf, self.tau, self.alpha)

    def complex_stiffness(self, frequency, amplitude):
        return self._split(self.continuous(2 * np.pi * np.asarray(frequency, dtype=float)), amplitude)


def Zener(k0, k_inf, tau, dt):  # noqa: N802 - named like the element classes it builds
    """Ordinary (three-parameter) Zener model: K0 parallel to a Maxwell branch (K_inf - K0, tau)."""
    return FractionalZener(k0, k_inf, tau, 1.0, dt)


class TwoOrderFractional(_ModeElement):
    """Seed 003's two-order fractional model (Eq. 22, complex stiffness Eq. 26), sum-of-exponentials scheme.

    k1, k2 [N/m]; c1 [N s^beta/m], c2 [N s^alpha/m]; alpha, beta in (0, 1]. Static stiffness k1.
    """

    def __init__(self, k1, k2, c1, c2, alpha, beta, dt, f_lo=1e-2, f_hi=None, per_decade=3.0):
        self.k1, self.k2, self.c1, self.c2 = float(k1), float(k2), float(c1), float(c2)
        self.alpha, self.beta = float(alpha), float(beta)
        f_hi = 0.5 / dt if f_hi is None else float(f_hi)
        # anchor the grid on the characteristic time where c1 s^beta ~ k2
        anchor = (self.c1 / self.k2) ** (1.0 / self.beta)
        u = relaxation_times(dt, f_lo, f_hi, anchor, per_decade)
        g, es, el = fit_modes(self.continuous, self.k1, u, f_lo, f_hi)
        keep = g > 0
        self.fit_error = (es, el)
        self._init_modes(self.k1, g[keep], u[keep], dt)

    def continuous(self, omega):
        return two_order_complex_stiffness(omega, self.k1, self.k2, self.c1, self.c2, self.alpha, self.beta)

    def complex_stiffness(self, frequency, amplitude):
        return self._split(self.continuous(2 * np.pi * np.asarray(frequency, dtype=float)), amplitude)


class FractionalZenerGL:
    """Fractional Zener with the paper's truncated Gruenwald-Letnikov scheme (seed 000 Eq. 9/15).

    ``n_terms`` = N_t, ``h`` [s] = GL step, an integer multiple of ``dt`` (default h = dt). The
    recursion is the difference equation (1 + c) F[n] + c sum_{i>=1} A_{i+1} F[n - i m]
    = K0 x[n] + K_inf c sum_{i>=0} A_{i+1} x[n - i m], c = tau^alpha h^-alpha, m = h/dt; batch runs
    it as one IIR filter (scipy lfilter) from the same history. Branches ('elastic', 'viscous').
    """

    kinds = ('elastic', 'viscous')
    branch_names = ('elastic', 'viscous')

    def __init__(self, k0, k_inf, tau, alpha, dt, n_terms=200, h=None):
        self.k0, self.k_inf, self.tau, self.alpha, self.dt = map(float, (k0, k_inf, tau, alpha, dt))
        self.h = self.dt if h is None else float(h)
        m = self.h / self.dt
        if m < 0.5 or abs(m - round(m)) > 1e-9 * m:
            raise ValueError(f'GL step h = {self.h:g} s must be an integer multiple of the sample period {self.dt:g} s')
        self.m, self.n_terms = int(round(m)), int(n_terms)
        if self.n_terms < 1:
            raise ValueError(f'parameter n_terms (N_t) must be >= 1, got {n_terms}')
        a = gl_coefficients(self.alpha, self.n_terms)
        c = self.tau ** self.alpha * self.h ** (-self.alpha)
        self.length = (self.n_terms - 1) * self.m + 1   # taps incl. the current sample
        self.b = np.zeros(self.length)
        self.a = np.zeros(self.length)
        self.b[::self.m] = self.k_inf * c * a
        self.b[0] += self.k0
        self.a[::self.m] = c * a
        self.a[0] = 1.0 + c
        # streaming: newest-first history vectors (x[n-1], x[n-2], ...)
        self._bx = self.b[1:].copy()
        self._af = self.a[1:].copy()
        self.reset()

    def static_stiffness(self):
        return self.b.sum() / self.a.sum()

    def reset(self, x0: float = 0.0):
        """History at rest at x0 [m], with the scheme's own static force (its K(0) is not exactly K0)."""
        f0 = self.static_stiffness() * float(x0)
        self.xh = np.full(self.length - 1, float(x0))
        self.fh = np.full(self.length - 1, f0)

    def get_state(self):
        return (self.xh.copy(), self.fh.copy())

    def set_state(self, state):
        self.xh, self.fh = np.array(state[0], float), np.array(state[1], float)

    def step(self, x: float):
        f = (self.b[0] * x + self._bx @ self.xh - self._af @ self.fh) / self.a[0]
        if self.xh.size:
            self.xh[1:] = self.xh[:-1]
            self.xh[0] = x
            self.fh[1:] = self.fh[:-1]
            self.fh[0] = f
        return (self.k0 * x, f - self.k0 * x)

    def run(self, x):
        x = np.asarray(x, dtype=float)
        if x.size == 0:
            return np.zeros((2, 0))
        if self.length == 1:
            f = self.b[0] * x / self.a[0]
        else:
            zi = lfiltic(self.b, self.a, self.fh, self.xh)
            f, _ = lfilter(self.b, self.a, x, zi=zi)
            k = self.length - 1
            self.xh = np.concatenate((x[::-1], self.xh))[:k]
            self.fh = np.concatenate((f[::-1], self.fh))[:k]
        return np.vstack([self.k0 * x, f - self.k0 * x])

    def complex_stiffness(self, frequency, amplitude):
        w = 2 * np.pi * np.asarray(frequency, dtype=float)
        k = zener_complex_stiffness(w, self.k0, self.k_inf, self.tau, self.alpha) + 0 * np.asarray(amplitude, float)
        return np.stack([np.full(k.shape, self.k0, dtype=complex), k - self.k0])

    def discrete_complex_stiffness(self, frequency):
        """Exact steady-state complex stiffness [N/m] of the GL recursion (seed 000 Eq. 14 for m = 1)."""
        q = np.exp(-2j * np.pi * np.asarray(frequency, dtype=float)[..., None] * self.dt * np.arange(self.length))
        return (q * self.b).sum(-1) / (q * self.a).sum(-1)
