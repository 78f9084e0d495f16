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

"""Steady-state properties of the seed-000 model evaluated the way a test rig measures them.

Seed 000 Eq. 17-27 combine Berg's friction element with the fractional Zener model through the
friction *peak* force F_f0 (Eq. 19) and a storage stiffness K_df*sqrt(1 - D_f^2) (Eq. 21). A rig,
and `rubber_rig.analysis.harmonic_properties`, measure K_dyn as the ratio of the *first harmonics*
of force and displacement and the energy as the loop area. The two agree exactly for the energy
(only the first harmonic of the force does work against a sine displacement, so E_f of Eq. 18 is
the loop area) but not for the friction storage stiffness: the Berg loop is not an ellipse and its
first harmonic differs from F_f0*sqrt(1 - D_f^2) by up to a few per cent (see `friction_first_harmonic`).
Fitting measured first-harmonic K_dyn with Eq. 24 would therefore bias K0 and the friction
parameters by about as much as the 2 % target, so the identification uses the first-harmonic form:

    K*(w, x0) = K_ev(jw) [Eq. 11]  +  (b1 + j a1)(x0) / x0       (first harmonic of the Berg loop)
    K_dyn = |K*|,  E = E_v + E_f = pi x0^2 Im K*,  C_eq = E / (pi w x0^2)  (Eq. 25-27)

The Berg steady loop scales exactly: F_f / F_fmax is a function of x / x2 alone (Eq. 16 with
x_s = -x0, F_fs = -F_f0), so the first harmonic is a Gauss-Legendre quadrature over one branch,
vectorised over any broadcast shape of parameters and amplitudes (the optimiser evaluates a
whole population at once).
"""
from __future__ import annotations

import numpy as np

from rubber_rig.models.fractional import zener_complex_stiffness
from rubber_rig.models.friction import (  # noqa: F401  (re-exported)
    berg_energy,
    berg_peak_force,
    friction_first_harmonic,
)


def measured_style_properties(k0, k_inf, tau, alpha, x2, f_fmax, frequency, amplitude):
    """K_dyn (first harmonic), loss angle, D, energy per cycle and C_eq of the seed-000 model.

    All arguments broadcast (SI units). Returns a dict of arrays, keys as
    `rubber_rig.analysis.harmonic_properties` plus `k_ev` / `k_f` (complex branch stiffnesses)
    and `r_k`, `r_e` (seed 000 Eq. 30, with first-harmonic friction stiffness).
    """
    omega = 2.0 * np.pi * np.asarray(frequency, float)
    x0 = np.asarray(amplitude, float)
    k_ev = zener_complex_stiffness(omega, *(np.asarray(v, float) for v in (k0, k_inf, tau, alpha)))
    k_f = friction_first_harmonic(f_fmax, x2, x0)
    k = k_ev + k_f
    k_dyn = np.abs(k)
    energy = np.pi * x0 ** 2 * k.imag
    loss_angle = np.angle(k)
    k_v = k_ev - np.asarray(k0, float)   # viscous branch F_v = F_ev - K0 x (Eq. 10)
    return {
        'frequency': np.broadcast_to(np.asarray(frequency, float), k_dyn.shape),
        'amplitude': np.broadcast_to(x0, k_dyn.shape),
        'k_dyn': k_dyn,
        'loss_angle': loss_angle,
        'damping': energy / (np.pi * x0 ** 2 * k_dyn),    # Eq. 26
        'energy': energy,
        'c_eq': energy / (np.pi * omega * x0 ** 2),        # Eq. 27
        'k_ev': k_ev,
        'k_f': k_f,
        'r_k': np.abs(k_v) / np.abs(k_f),                  # Eq. 30
        'r_e': k_ev.imag / k_f.imag,
    }
