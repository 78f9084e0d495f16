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

Each branch contributes an (equivalent) complex stiffness K_b = K_bs + j K_bl, and (Eq. 23-27)
K_dyn = |sum K_b|, E = pi x0^2 sum K_bl, D = E / (pi x0^2 K_dyn) = sin(delta), C_eq = E / (pi w x0^2),
and (Eq. 30) R_K = K_dv / K_df, R_E = E_v / E_f with K_dv = |sum of the viscous branches| and
K_df = |sum of the friction branches|. Linear elements (Eq. 11-13) are exact in both definitions of
K_b for the non-linear ones (``kdyn``):

* ``'harmonic'`` -- the exact first harmonic: K_b = F_b1 / X1, the ratio of the first harmonics of
  the branch force and the displacement. This is what a rig (and ``--method time``, and
  :func:`rubber_rig.analysis.harmonic_properties`) measures. Berg's loop by quadrature
  (:func:`.friction.friction_first_harmonic`), memoryless non-linear springs by their first
  harmonic (the describing function). The default, as in ``rubber-rig props``; the same K1 as the
  catalogue's ``ModelSpec.first_harmonic`` that the fits use.
* ``'eq24'`` -- seed 000 Eq. 19-24 as printed (ask for it to reproduce the paper's numbers): Berg's
  loop replaced by the ellipse of equal peak force and energy, K_f = K_df (sqrt(1 - D_f^2) + j D_f)
  with K_df = F_f0 / x0 (Eq. 19-22), and memoryless springs by their peak secant
  (F(x0) - F(-x0)) / (2 x0): each element's own ``complex_stiffness``.

The loss parts, hence E, D's numerator, C_eq and R_E, are the same in both (only the first harmonic of
the force does work against a sine displacement); K_dyn, the loss angle, D and R_K differ. For the
four seed-000 temperature sets over 0.5-14 Hz at 0.5 and 1 mm, eq24's K_dyn is below the first harmonic
by 0.08-0.16 % at 20 degC and up to 1.03 % at -40 degC (0.5 Hz, 1 mm; 0.99 % at 1.3 Hz), its R_K above
by up to 4.3 % (-40 degC, 1 mm).
"""
from __future__ import annotations

import numpy as np

from .composite import ParallelModel, build_model
from .friction import BergFriction, friction_first_harmonic

KDYN_DEFINITIONS = ('harmonic', 'eq24')
# midpoints of a whole period: spectrally accurate for the smooth periodic integrand F(x0 sin theta) sin theta
_N_THETA = 256
_SIN_THETA = np.sin((np.arange(_N_THETA) + 0.5) * 2 * np.pi / _N_THETA)


def _model_for(params):
    if isinstance(params, ParallelModel):
        return params
    # the analytic forms are the continuous ones whatever the scheme: pick the cheapest to build
    # (no sum-of-exponentials fit), since fitting code calls this in its inner loop
    return build_model(params, dt=1e-3, scheme={'name': 'gl', 'n_terms': 1})


def check_kdyn(kdyn) -> str:
    """``kdyn`` if it names a K_dyn definition ('harmonic' or 'eq24'), else ValueError."""
    if kdyn not in KDYN_DEFINITIONS:
        raise ValueError(f"kdyn must be 'harmonic' (exact first harmonic) or 'eq24' (seed 000 Eq. 24 ellipse), "
                         f'got {kdyn!r}')
    return kdyn


def _is_memoryless_spring(element) -> bool:
    return tuple(getattr(element, 'kinds', ())) == ('elastic',) and callable(getattr(element, 'force', None))


def _first_harmonic_spring(element, frequency, amplitude):
    """First-harmonic stiffness b1 / x0 of a memoryless spring F(x) under x = x0 sin(theta), shape (1, ...)."""
    f, x0 = np.broadcast_arrays(np.asarray(frequency, float), np.asarray(amplitude, float))
    xs = x0[..., None] * _SIN_THETA
    k = 2.0 * np.mean(np.asarray(element.force(xs), float) * _SIN_THETA, axis=-1) / x0
    return np.asarray(k + 0 * f, dtype=complex)[None]


def branch_stiffness(model, frequency, amplitude, kdyn='harmonic') -> np.ndarray:
    """Complex stiffness per branch [N/m], shape (n_branch, ...), in the ``kdyn`` definition (module doc)."""
    if check_kdyn(kdyn) == 'eq24':
        return model.complex_stiffness(frequency, amplitude)
    f = np.asarray(frequency, float)
    parts = []
    for e in model.elements:
        if isinstance(e, BergFriction):
            parts.append(np.asarray(friction_first_harmonic(e.f_fmax, e.x2, amplitude) + 0 * f)[None])
        elif _is_memoryless_spring(e):
            parts.append(_first_harmonic_spring(e, f, amplitude))
        else:   # linear elements (exact) and those whose complex_stiffness is already a first harmonic
            parts.append(e.complex_stiffness(f, amplitude))
    return np.concatenate(parts)


def steady_state_properties(params, frequency, amplitude, kdyn='harmonic') -> dict:
    """Analytic steady-state properties of a model at ``frequency`` [Hz] and ``amplitude`` [m] (broadcast).

    ``params``: any model source ``build_model`` accepts (parameters, a set name, a model file...) or a model.
    ``kdyn``: 'harmonic' (exact first harmonic, what a rig and ``time_domain_properties`` measure; the
    default, as in ``rubber-rig props``) or 'eq24' (seed 000 Eq. 19-24 ellipse form, for reproducing the
    paper's numbers); see the module doc. K_dyn, loss_angle, damping, k_storage, k_df and r_k follow it.
    Returns a dict of arrays (floats for scalar input): frequency [Hz], amplitude [m], k_dyn [N/m],
    loss_angle [rad], damping [-] (Eq. 26), c_eq [N s/m] (Eq. 27), energy [J per cycle] (Eq. 25 + 18),
    r_k, r_e [-] (Eq. 30; inf without friction), k_storage, k_loss [N/m], energy_viscous,
    energy_friction [J], k_dv, k_df [N/m], branches {name: complex stiffness [N/m]}, kdyn_definition.
    """
    check_kdyn(kdyn)
    model = _model_for(params)
    f, x0 = np.broadcast_arrays(np.asarray(frequency, dtype=float), np.asarray(amplitude, dtype=float))
    if np.any(~np.isfinite(f)) or np.any(f <= 0):
        raise ValueError('frequency must be finite and > 0 Hz')
    if np.any(~np.isfinite(x0)) or np.any(x0 <= 0):
        raise ValueError('amplitude must be finite and > 0 m')
    kb = branch_stiffness(model, f, x0, kdyn)                 # (n_branch, ...)
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
    out['kdyn_definition'] = kdyn
    return out
