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

"""Steady-state harmonic properties of a measured or simulated force-displacement record (seed 000 Eq. 2-3, 27)."""
from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class HarmonicProperties:
    """Properties over ``cycles`` whole cycles. SI units; loss_angle in rad."""

    frequency: float        # [Hz]
    amplitude: float        # [m] first-harmonic displacement amplitude x1
    mean: float             # [m] mean displacement
    k_dyn: float            # [N/m] |F1| / |x1| (first harmonic)
    loss_angle: float       # [rad] phase of F1 relative to x1
    damping: float          # [-] D = E_loop / (pi x1^2 k_dyn) (Eq. 3)
    c_eq: float             # [N s/m] E_loop / (pi w x1^2) (Eq. 27)
    energy_harmonic: float  # [J] pi |x1| |F1| sin(loss_angle) per cycle
    energy_loop: float      # [J] loop area per cycle, trapezoid
    k_peak: float           # [N/m] (F_max - F_min) / (x_max - x_min), Eq. 2 with peak amplitudes
    force_mean: float       # [N]
    cycles: int
    samples: int
    peak_amplitude: float   # [m] half the peak-to-peak displacement (first harmonic of a triangle: 8/pi^2 of it)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def estimate_frequency(x, dt: float) -> float:
    """Dominant frequency [Hz] of ``x`` (FFT peak refined by parabolic interpolation of log magnitude)."""
    x = np.asarray(x, dtype=float)
    n = x.size
    if n < 4:
        raise ValueError('need at least 4 samples to estimate a frequency')
    win = np.hanning(n)
    spec = np.abs(np.fft.rfft((x - x.mean()) * win))
    k = int(np.argmax(spec[1:]) + 1)
    if 1 <= k < spec.size - 1 and np.all(spec[k - 1:k + 2] > 0):
        a, b, c = np.log(spec[k - 1:k + 2])
        k = k + 0.5 * (a - c) / (a - 2 * b + c)
    return float(k / (n * dt))


def harmonic_properties(x, force, dt: float, frequency: float = None,
                        whole_cycles: int | None = None) -> HarmonicProperties:
    """First-harmonic and loop properties over the last whole number of cycles of (x [m], force [N]).

    x, force: 1-D arrays sampled every ``dt`` [s]. ``frequency`` [Hz] of the excitation; estimated
    from ``x`` when None. Uses the last floor(n dt f) cycles (the end of a record is the most
    settled); needs at least one full cycle. The first-harmonic fit always has a linear-drift column:
    it keeps drift (thermal, or a decaying transient) out of F1, at the price of a small leak of a
    non-sinusoidal force's odd harmonics into F1 (~0.6 % / cycles for a Berg loop).
    ``whole_cycles``: the record was cut at sampled crossings and spans this many cycles from its
    first to its last sample (the loop closes on the last sample) although ``frequency`` says the
    period is a fraction of a sample longer or shorter; then all samples are used.
    """
    x = np.asarray(x, dtype=float)
    force = np.asarray(force, dtype=float)
    if x.shape != force.shape or x.ndim != 1:
        raise ValueError(f'x and force must be 1-D arrays of equal length, got {x.shape} and {force.shape}')
    if not np.all(np.isfinite(x)) or not np.all(np.isfinite(force)):
        raise ValueError('x and force must be finite')
    f = estimate_frequency(x, dt) if frequency is None else float(frequency)
    if not f > 0:
        raise ValueError(f'frequency must be > 0 Hz, got {f}')
    period = 1.0 / (f * dt)                      # samples per cycle (may be fractional)
    if whole_cycles is not None:
        cycles, m = int(whole_cycles), x.size - 1
        if cycles < 1 or m < 2:
            raise ValueError(f'whole_cycles must be >= 1 over >= 3 samples, got {whole_cycles} over {x.size}')
    else:
        cycles = int(np.floor((x.size - 1) / period + 1e-9))
        if cycles < 1:
            raise ValueError(f'record of {x.size} samples is shorter than one cycle ({period:.1f} samples)')
        m = int(round(cycles * period))          # samples spanning the whole cycles
    xs, fs = x[-(m + 1):], force[-(m + 1):]      # m + 1 points: the loop closes on itself
    t = np.arange(m) * dt
    w = 2 * np.pi * f
    # a linear trend column keeps slow drift (thermal, or a decaying simulation transient) out of F1
    basis = np.column_stack([np.ones(m), np.cos(w * t), np.sin(w * t), t - t.mean()])
    cx, *_ = np.linalg.lstsq(basis, xs[:-1], rcond=None)
    cf, *_ = np.linalg.lstsq(basis, fs[:-1], rcond=None)
    x1 = cx[1] - 1j * cx[2]                      # phasor of a cos + b sin = Re(X e^{jwt})
    if not abs(x1) > 0:
        raise ValueError('displacement has no component at the excitation frequency')
    f1 = cf[1] - 1j * cf[2]
    k1 = f1 / x1
    amp = abs(x1)
    # loop area as a closed polygon (the segment from the last point back to the first closes it): a
    # record that does not quite return to its start (a cut at sampled crossings) would otherwise add
    # mean force x gap, e.g. 1.5 kN preload x 40 um = 10 % of a 14 Hz loop
    e_loop = float(np.sum(0.5 * (fs[1:] + fs[:-1]) * np.diff(xs))
                   + 0.5 * (fs[0] + fs[-1]) * (xs[0] - xs[-1])) / cycles
    k_dyn = abs(k1)
    xr = xs.max() - xs.min()
    return HarmonicProperties(
        frequency=f, amplitude=amp, mean=float(xs[:-1].mean()), k_dyn=k_dyn, loss_angle=float(np.angle(k1)),
        damping=e_loop / (np.pi * amp ** 2 * k_dyn), c_eq=e_loop / (np.pi * w * amp ** 2),
        energy_harmonic=float(np.pi * amp * abs(f1) * np.sin(np.angle(k1))), energy_loop=e_loop,
        k_peak=float((fs.max() - fs.min()) / xr) if xr > 0 else float('nan'), force_mean=float(fs[:-1].mean()),
        cycles=cycles, samples=m, peak_amplitude=0.5 * float(xr))
