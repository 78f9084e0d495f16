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

"""Fractional-derivative viscoelastic elements: closed forms and the two time-domain schemes.

Fractional Zener, seed 000 Eq. 4: F + tau^a D^a F = K0 x + K_inf tau^a D^a x, complex stiffness
(Eq. 11-13) K(jw) = (K0 + K_inf (jw tau)^a) / (1 + (jw tau)^a).

Scheme "gl" (the paper's, Eq. 7-9/15): Gruenwald-Letnikov sum truncated at N_t terms with step h
(h an integer multiple of the sample period). Its steady-state complex stiffness is Eq. 14; the
truncation makes it lose loss stiffness at low frequency (-28 % at 0.5 Hz, -64 % at 0.1 Hz with
the 20 degC parameters, N_t = 200, h = 1 ms). Cost O(N_t) per sample.

Scheme "default" (sum of exponentials, diffusive representation): for 0 < a < 1,
1/(1 + (s tau)^a) is a Stieltjes function - a positive (Cole-Cole) distribution of relaxation
times - so K(s) = K0 + (K_inf - K0) * int H(u) s u/(1 + s u) du is a continuous generalised
Maxwell model. It is replaced by M modes with relaxation times log-spaced at 2 per decade on a grid
through tau, from 1/(20 pi f_hi) (a decade above Nyquist) to 10/(2 pi f_lo) (a decade below
f_lo = 10 mHz), with non-negative weights from a least-squares fit of the *relative* storage and
loss errors of Eq. 11 over [f_lo, f_hi = fs/2] (see :mod:`.modes`); NNLS leaves M ~ 12-15 active
modes. Each mode is discretised exactly for piecewise-linear input. K0 is kept exact (static
stiffness), the recursion is passive and unconditionally stable, and the cost per sample is O(M),
independent of the history length.

Error bound (steady state, 0.05-50 Hz, for Table 1 and every temperature interpolated between;
computed exactly from the discrete transfer function by
``FractionalZener.discrete_complex_stiffness`` and checked by time-domain runs in the tests):
storage stiffness within 0.15 %, loss stiffness within 0.9 % at 1 kHz and within 0.6 % at 5 kHz.
The loss error at 1 kHz is dominated by the discretisation, about (w h)^2/12 (0.82 % at 50 Hz);
the fit itself is good to about 0.1 % storage and 0.6 % loss (reported as ``fit_error``).
Below f_lo the modes' loss falls as w instead of w^alpha; above f_hi no accuracy is claimed. The bound holds
for 0.1 <= alpha <= 1 (measured at 1 kHz with Table 1's 20 degC stiffnesses and tau: storage <= 0.03 %, loss
<= 0.9 % from alpha 0.1 to 0.99; at alpha 0.05 the loss error is 1.5 %, at 0.01 the storage error 5.3 %), and
the element refuses an alpha below 0.1 (elements.FractionalZener.ALPHA_MIN).
For alpha = 1 the model is the ordinary Zener model with one exact mode.

Two-order fractional model, seed 003 Eq. 22/26: K(s) = k1 + c1 s^b (k2 + c2 s^a) /
(c1 s^b + k2 + c2 s^a) (a spring k1 parallel to a fractional dashpot c1 s^b in series with k2 +
c2 s^a); time domain by the same sum-of-exponentials fit (its spectrum is fitted, not derived).
"""
from __future__ import annotations

import numpy as np


def zener_complex_stiffness(omega, k0, k_inf, tau, alpha):
    """Fractional Zener complex stiffness [N/m] at circular frequency ``omega`` [rad/s] (seed 000 Eq. 11).

    Real part = storage stiffness (Eq. 12), imaginary part = loss stiffness (Eq. 13). Broadcasts.
    """
    s_a = (1j * np.asarray(omega, dtype=float) * tau) ** alpha
    return (k0 + k_inf * s_a) / (1.0 + s_a)


def zener_storage_loss(omega, k0, k_inf, tau, alpha):
    """Storage and loss stiffness [N/m] written out as in seed 000 Eq. 12 and Eq. 13."""
    wt = (np.asarray(omega, dtype=float) * tau) ** alpha
    c, s = np.cos(alpha * np.pi / 2), np.sin(alpha * np.pi / 2)
    den = 1.0 + wt ** 2 + 2.0 * wt * c
    return (k0 + (k0 + k_inf) * wt * c + k_inf * wt ** 2) / den, (k_inf - k0) * wt * s / den


def gl_coefficients(alpha: float, n_terms: int) -> np.ndarray:
    """Gruenwald coefficients A_1..A_N (seed 000 Eq. 6): A_1 = 1, A_{i+1} = (1 - (alpha + 1)/i) A_i."""
    a = np.ones(int(n_terms))
    for i in range(1, int(n_terms)):
        a[i] = (1.0 - (alpha + 1.0) / i) * a[i - 1]
    return a


def gl_complex_stiffness(omega, k0, k_inf, tau, alpha, n_terms=200, h=1e-3):
    """Steady-state complex stiffness [N/m] of the truncated GL scheme (seed 000 Eq. 14).

    ``n_terms`` = N_t, ``h`` [s] the GL step. Broadcasts over ``omega`` [rad/s].
    """
    a = gl_coefficients(alpha, n_terms)
    w = np.asarray(omega, dtype=float)
    phase = np.exp(-1j * np.multiply.outer(w * h, np.arange(len(a))))
    s = (phase * a).sum(-1)
    c = tau ** alpha * h ** (-alpha)
    return (k0 + k_inf * c * s) / (1.0 + c * s)


def two_order_complex_stiffness(omega, k1, k2, c1, c2, alpha, beta):
    """Complex stiffness [N/m] of seed 003's two-order fractional model (Eq. 26), at ``omega`` [rad/s]."""
    s = 1j * np.asarray(omega, dtype=float)
    sa, sb = s ** alpha, s ** beta
    lam1, lam2 = c2 / c1, k2 / c1
    return ((k1 + k2) * sb + lam1 * k1 * sa + lam2 * k1 + c2 * sa * sb) / (sb + lam1 * sa + lam2)
