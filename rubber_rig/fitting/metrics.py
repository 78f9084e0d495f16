"""Per-block measured properties: one code path for measurements and for time-domain model runs.

The numbers come from `rubber_rig.analysis.harmonic_properties` (the models engineer's function, so
that measured data and simulated model output are evaluated identically). Until that module is
importable this falls back to a local implementation of the same definitions.
"""
from __future__ import annotations

import numpy as np


def _local_harmonic_properties(x, force, dt, frequency=None):
    """First-harmonic K_dyn and loss angle, loop-area energy, D (Eq. 26) and C_eq (Eq. 27)."""
    x = np.asarray(x, float)
    force = np.asarray(force, float)
    n = x.size
    t = np.arange(n) * dt
    if frequency is None:
        spec = np.abs(np.fft.rfft(x - x.mean()))
        k = int(np.argmax(spec[1:]) + 1)
        frequency = k / (n * dt)
    w = 2.0 * np.pi * frequency
    basis = np.column_stack([np.ones(n), np.sin(w * t), np.cos(w * t)])
    cx, *_ = np.linalg.lstsq(basis, x, rcond=None)
    cf, *_ = np.linalg.lstsq(basis, force, rcond=None)
    x1 = cx[1] + 1j * cx[2]
    f1 = cf[1] + 1j * cf[2]
    k = f1 / x1
    amplitude = abs(x1)
    cycles = n * dt * frequency
    # loop area over the analysed (whole) cycles, trapezoidal, per cycle
    energy_loop = float(np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(x))) / cycles
    energy_harm = np.pi * amplitude ** 2 * k.imag
    return {
        'k_dyn': float(abs(k)), 'loss_angle': float(np.angle(k)),
        'damping': energy_loop / (np.pi * amplitude ** 2 * abs(k)),
        'c_eq': energy_loop / (np.pi * w * amplitude ** 2),
        'energy_harmonic': float(energy_harm), 'energy_loop': energy_loop,
        'frequency': float(frequency), 'amplitude': float(amplitude), 'mean': float(cx[0]),
    }


def harmonic_properties(x, force, dt, frequency=None) -> dict:
    try:
        from rubber_rig.analysis import harmonic_properties as shared
    except ImportError:
        shared = _local_harmonic_properties
    out = dict(shared(x, force, dt, frequency=frequency))
    return {k: (float(v) if np.ndim(v) == 0 else v) for k, v in out.items()}
