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

"""Analytic steady-state properties under x = x0 sin(2 pi f t) (seed 000 Eq. 11-13, 17-27, 30).

Each branch contributes an (equivalent) complex stiffness K_b = K_bs + j K_bl: exact for linear
elements (Eq. 11-13), Berg's equal-peak-force, equal-energy ellipse for friction (Eq. 19-22).
Then (Eq. 23-27): K_dyn = |sum K_b|, E = pi x0^2 sum K_bl, D = E / (pi x0^2 K_dyn) = sin(delta),
C_eq = E / (pi w x0^2), and (Eq. 30) R_K = K_dv / K_df, R_E = E_v / E_f with K_dv = |sum of the
viscous branches| and K_df = |sum of the friction branches|.
"""
from __future__ import annotations

import numpy as np

from .composite import ParallelModel, build_model


def _model_for(params):
    if isinstance(params, ParallelModel):
        return params
    # the analytic forms are the continuous ones whatever the scheme: pick the cheapest to build
    # (no sum-of-exponentials fit), since fitting code calls this in its inner loop
    return build_model(params, dt=1e-3, scheme={'name': 'gl', 'n_terms': 1})


def steady_state_properties(params, frequency, amplitude) -> dict:
    """Analytic steady-state properties of a model at ``frequency`` [Hz] and ``amplitude`` [m] (broadcast).

    ``params``: Seed000Params (or any spec accepted by ``build_model``, or a model object).
    Returns a dict of arrays (floats for scalar input): frequency [Hz], amplitude [m], k_dyn [N/m],
    loss_angle [rad], damping [-] (Eq. 26), c_eq [N s/m] (Eq. 27), energy [J per cycle] (Eq. 25 + 18),
    r_k, r_e [-] (Eq. 30; inf without friction), k_storage, k_loss [N/m], energy_viscous,
    energy_friction [J], k_dv, k_df [N/m], branches {name: complex stiffness [N/m]}.
    """
    model = _model_for(params)
    f, x0 = np.broadcast_arrays(np.asarray(frequency, dtype=float), np.asarray(amplitude, dtype=float))
    if np.any(~np.isfinite(f)) or np.any(f <= 0):
        raise ValueError('frequency must be finite and > 0 Hz')
    if np.any(~np.isfinite(x0)) or np.any(x0 <= 0):
        raise ValueError('amplitude must be finite and > 0 m')
    kb = model.complex_stiffness(f, x0)                       # (n_branch, ...)
    kinds = np.array(model.branch_kinds)
    k = kb.sum(axis=0)
    k_dyn = np.abs(k)
    e_b = np.pi * x0 ** 2 * kb.imag
    energy = e_b.sum(axis=0)
    omega = 2 * np.pi * f
    k_v = kb[kinds == 'viscous'].sum(axis=0)
    k_f = kb[kinds == 'friction'].sum(axis=0)
    e_v, e_f = e_b[kinds == 'viscous'].sum(axis=0), e_b[kinds == 'friction'].sum(axis=0)
    with np.errstate(divide='ignore', invalid='ignore'):
        r_k = np.where(np.abs(k_f) > 0, np.abs(k_v) / np.abs(k_f), np.inf)
        r_e = np.where(e_f > 0, e_v / e_f, np.inf)
    out = {
        'frequency': f, 'amplitude': x0, 'k_dyn': k_dyn, 'loss_angle': np.arctan2(k.imag, k.real),
        'damping': energy / (np.pi * x0 ** 2 * k_dyn), 'c_eq': energy / (np.pi * omega * x0 ** 2),
        'energy': energy, 'r_k': r_k, 'r_e': r_e, 'k_storage': k.real, 'k_loss': k.imag,
        'energy_viscous': e_v, 'energy_friction': e_f, 'k_dv': np.abs(k_v), 'k_df': np.abs(k_f),
    }
    if f.ndim == 0:
        out = {key: float(v) for key, v in out.items()}
        out['branches'] = {n: complex(v) for n, v in zip(model.branch_names, kb, strict=False)}
    else:
        out['branches'] = dict(zip(model.branch_names, kb, strict=False))
    return out
