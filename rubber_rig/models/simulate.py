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

"""Time-domain steady state: drive a model with a sine and measure it like a test rig does."""
from __future__ import annotations

import numpy as np

from ..analysis import harmonic_properties


def sine_displacement(frequency: float, amplitude: float, dt: float, cycles: float, offset: float = 0.0):
    """x(t) = offset + amplitude sin(2 pi f t) [m], t = n dt for ``cycles`` whole cycles (n >= 0)."""
    n = int(round(cycles / (frequency * dt)))
    t = np.arange(n + 1) * dt
    return offset + amplitude * np.sin(2 * np.pi * frequency * t)


def time_domain_properties(model, frequency: float, amplitude: float, cycles: int = 30,
                           analysed_cycles: int = 2, offset: float = 0.0) -> dict:
    """Steady-state properties of ``model`` (from ``build_model``, reset first) from a sine run.

    Runs ``cycles`` cycles of x = offset + amplitude sin(2 pi f t) [m] at the model's dt and
    analyses the last ``analysed_cycles`` (Berg's loop needs ~20 cycles from the virgin state to
    settle within 1e-5, the slow fractional modes a few) with :func:`rubber_rig.analysis.harmonic_properties`
    (k_dyn from the first harmonic, energy per cycle pi x1 F1 sin(delta), D = E/(pi x1^2 K_dyn)
    (Eq. 26), C_eq (Eq. 27)). Per-branch energies give R_E, per-branch peak force amplitudes
    give R_K (seed 000 Eq. 30; the friction amplitude is the peak force of Eq. 17/19).
    Returns the keys of ``steady_state_properties`` (values as floats).
    """
    model.reset(offset)
    x = sine_displacement(frequency, amplitude, model.dt, cycles, offset)
    total, branches = model.run(x, return_branches=True)
    n = int(round(analysed_cycles / (frequency * model.dt))) + 1
    xs = x[-n:]
    h = harmonic_properties(xs, total[-n:], model.dt, frequency)
    kinds = np.array(model.branch_kinds)
    # for a sinusoidal x only the first harmonic of F does work: pi x1 F1 sin(delta) is the exact
    # energy per cycle, free of the trapezoid loop-area error at few samples per cycle
    e = h.energy_harmonic

    def part(kind):
        sel = kinds == kind
        if not sel.any():
            return 0.0, 0.0
        hp = harmonic_properties(xs, branches[sel].sum(axis=0)[-n:], model.dt, frequency)
        # Eq. 30 uses force amplitudes (Eq. 19: peak friction force), energies per cycle
        return hp.k_peak, hp.energy_harmonic

    k_dv, e_v = part('viscous')
    k_df, e_f = part('friction')
    return {
        'frequency': float(frequency), 'amplitude': float(h.amplitude), 'k_dyn': h.k_dyn,
        'loss_angle': h.loss_angle, 'damping': float(np.sin(h.loss_angle)),
        'c_eq': e / (2 * np.pi ** 2 * frequency * h.amplitude ** 2), 'energy': e, 'energy_loop': h.energy_loop,
        'r_k': k_dv / k_df if k_df > 0 else float('inf'), 'r_e': e_v / e_f if e_f > 0 else float('inf'),
        'k_peak': h.k_peak, 'energy_viscous': e_v, 'energy_friction': e_f, 'k_dv': k_dv, 'k_df': k_df,
    }
