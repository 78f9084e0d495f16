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

"""Time-domain steady state: drive a model with a sine and measure it like a test rig does.

K_dyn is the exact first harmonic F1 / X1 (the ``'harmonic'`` definition of
:func:`.steady_state.steady_state_properties`), taken over a whole number of cycles: the analysed
window is the last ``analysed_cycles`` cycles, m = round(analysed_cycles / (f dt)) sample intervals.
When a cycle is a whole number of samples (build the model at :func:`whole_cycle_dt`, as
``rubber-rig props --method time`` does) the window is exactly analysed_cycles periods and the fit below
is the DFT bin of the excitation: no leakage of the loop's higher harmonics at all. Otherwise the window
is off by under half a sample, and the fit leaks at most ~1/m of the higher harmonics.

The first harmonic is a least-squares fit of [1, cos wt, sin wt] at the excitation frequency, without the
linear-drift column of :func:`rubber_rig.analysis.harmonic_properties`: a settled simulation does not
drift, and that column correlates with every harmonic (t is not orthogonal to sin k w t over whole
cycles), so it leaked the Berg loop's odd harmonics into F1 (+0.09 % K_dyn over 2 cycles at -40 degC,
1.3 Hz, 1 mm). The old window test also rounded 2 cycles of 769.23 samples (1.3 Hz at 1 kHz) down to
one, where that leak is +0.87 %.
"""
from __future__ import annotations

import numpy as np

from ..analysis import harmonic_properties


def whole_cycle_dt(frequency: float, rate: float) -> float:
    """Sample period [s] nearest 1 / ``rate`` with a whole number n = round(rate / f) >= 1 of samples per cycle.

    The sample rate f n differs from ``rate`` by at most f / 2 (relative f / (2 rate): 0.065 % at 1.3 Hz and
    1 kHz, 0.6 % at 14 Hz).
    """
    frequency, rate = float(frequency), float(rate)
    if not (frequency > 0 and rate > 0 and np.isfinite(frequency) and np.isfinite(rate)):
        raise ValueError(f'frequency and rate must be finite and > 0 Hz, got {frequency} and {rate}')
    return 1.0 / (frequency * max(1, round(rate / frequency)))


def sine_displacement(frequency: float, amplitude: float, dt: float, cycles: float, offset: float = 0.0):
    """x(t) = offset + amplitude sin(2 pi f t) [m], t = n dt for ``cycles`` whole cycles (n >= 0)."""
    n = int(round(cycles / (frequency * dt)))
    t = np.arange(n + 1) * dt
    return offset + amplitude * np.sin(2 * np.pi * frequency * t)


def first_harmonics(signals, dt: float, frequency: float) -> np.ndarray:
    """Complex first-harmonic amplitudes (phasors, a cos + b sin -> a - j b) of the rows of ``signals``.

    Least squares on [1, cos w t, sin w t] over all samples (no drift term); over a whole number of
    periods of whole samples this is exactly the DFT bin of the excitation.
    """
    y = np.atleast_2d(np.asarray(signals, dtype=float))
    m = y.shape[-1]
    wt = 2 * np.pi * frequency * dt * np.arange(m)
    basis = np.column_stack([np.ones(m), np.cos(wt), np.sin(wt)])
    c, *_ = np.linalg.lstsq(basis, y.T, rcond=None)
    return c[1] - 1j * c[2]


def time_domain_properties(model, frequency: float, amplitude: float, cycles: int = 30,
                           analysed_cycles: int = 2, offset: float = 0.0) -> dict:
    """Steady-state properties of ``model`` (from ``build_model``, reset first) from a sine run.

    Runs ``cycles`` cycles of x = offset + amplitude sin(2 pi f t) [m] at the model's dt and analyses the
    last ``analysed_cycles`` (Berg's loop needs ~20 cycles from the virgin state to settle within 1e-5,
    the slow fractional modes a few) as the module doc says: K_dyn = |F1 / X1| (the exact first harmonic,
    ``kdyn='harmonic'`` of ``steady_state_properties``), loss angle = arg(F1 / X1), energy per cycle
    pi Im(F1 conj(X1)) (exact: only the first harmonic of F does work against a sine, and free of the
    trapezoid loop-area error at few samples per cycle), D = E / (pi x1^2 K_dyn) (Eq. 26), C_eq (Eq. 27).
    Per branch b, K_b = F_b1 / X1 gives E_v, E_f and (Eq. 30, first-harmonic definition) R_K = |K_v| / |K_f|,
    R_E = E_v / E_f. Returns the keys of ``steady_state_properties`` (values as floats), with
    kdyn_definition = 'harmonic', plus energy_loop (loop area per cycle), k_peak (peak-to-peak force over
    peak-to-peak displacement), k_df_peak (the friction branches' peak-to-peak force over peak-to-peak
    displacement: Eq. 19's F_f0 / x0), cycles_analysed and samples_per_cycle.
    """
    if int(analysed_cycles) < 1 or int(cycles) <= int(analysed_cycles):
        raise ValueError(f'need cycles > analysed_cycles >= 1, got cycles={cycles}, analysed_cycles={analysed_cycles}')
    model.reset(offset)
    x = sine_displacement(frequency, amplitude, model.dt, cycles, offset)
    total, branches = model.run(x, return_branches=True)
    n = analysed_cycles
    m = int(round(n / (frequency * model.dt)))      # sample intervals spanning the analysed cycles
    xs, fs, bs = x[-(m + 1):], total[-(m + 1):], branches[:, -(m + 1):]
    h = harmonic_properties(xs, fs, model.dt, frequency, whole_cycles=n)   # loop area, peak-to-peak stiffness
    x1, f1, *b1 = first_harmonics(np.vstack([xs, fs, bs])[:, :-1], model.dt, frequency)
    k = f1 / x1
    kb = np.array(b1) / x1
    amp = abs(x1)
    e = float(np.pi * amp ** 2 * k.imag)
    kinds = np.array(model.branch_kinds)
    k_v, k_f = kb[kinds == 'viscous'].sum(), kb[kinds == 'friction'].sum()
    e_v, e_f = float(np.pi * amp ** 2 * k_v.imag), float(np.pi * amp ** 2 * k_f.imag)
    k_dv, k_df = float(abs(k_v)), float(abs(k_f))
    friction_force = bs[kinds == 'friction'].sum(axis=0)
    xr = float(xs.max() - xs.min())
    k_dyn = float(abs(k))
    return {
        'frequency': float(frequency), 'amplitude': float(amp), 'k_dyn': k_dyn,
        'loss_angle': float(np.angle(k)), 'damping': e / (np.pi * amp ** 2 * k_dyn),
        'c_eq': e / (2 * np.pi ** 2 * frequency * amp ** 2), 'energy': e, 'energy_loop': h.energy_loop,
        'r_k': k_dv / k_df if k_df > 0 else float('inf'), 'r_e': e_v / e_f if e_f > 0 else float('inf'),
        'k_storage': float(k.real), 'k_loss': float(k.imag),
        'k_peak': h.k_peak, 'energy_viscous': e_v, 'energy_friction': e_f, 'k_dv': k_dv, 'k_df': k_df,
        'k_df_peak': float(np.ptp(friction_force) / xr) if xr > 0 else float('nan'),
        'kdyn_definition': 'harmonic', 'cycles_analysed': n, 'samples_per_cycle': 1.0 / (frequency * model.dt),
    }
