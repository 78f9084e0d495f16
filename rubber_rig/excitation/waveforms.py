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

"""Unit waveform shapes, phase laws and taper envelopes, evaluated vectorised from sample times.

All functions take numpy arrays and return arrays of the same shape. Phase is in cycles (1.0 = one period).
Which waveforms exist, and what each one needs, is the registry in waveform_types.py.
"""
import functools

import numpy as np


def smoothstep(u):
    """Raised cosine 0 -> 1 on u in [0, 1] (clipped outside): zero slope at both ends, so no velocity jump."""
    u = np.clip(u, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * u)


def triangle(phase):
    """Unit triangle starting at 0 going up, peak +1 at phase 0.25, -1 at 0.75 (slope 4 per cycle)."""
    return 4.0 * np.abs(np.mod(phase - 0.25, 1.0) - 0.5) - 1.0


def sine(phase):
    """Unit sine: sin(2 pi phase)."""
    return np.sin(2.0 * np.pi * phase)


def square(phase, square_slope: float):
    """Unit square (trapezoid): the triangle steepened by square_slope (>= 1) and clipped to -1..1; the edges
    then take 1/square_slope of a quarter period each, which realises a set transition rate.
    """
    return np.clip(square_slope * triangle(phase), -1.0, 1.0)


def haversine(phase):
    """Unit haversine pulse train (1 - cos(2 pi phase)) / 2: from 0 up to 1 at phase 0.5 and back to 0, with zero
    slope at 0 (one-sided pulses from the base level; peak slope pi per cycle at phase 0.25).
    """
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * phase)


# ---- random-phase multisine: equal-amplitude lines at whole multiples of the base frequency
_MULTISINE_GRID = 64          # grid points per period of the highest line for the peak search
_MULTISINE_CHUNK = 1 << 15    # samples evaluated at once


@functools.lru_cache(maxsize=32)
def multisine_lines(first: int, last: int, seed: int):
    """The lines of a unit multisine with harmonics first..last of its base frequency and random phases.

    u(phase) = sum_k sin(2 pi n_k phase + phi_k) / S, phi_k uniform in [0, 2 pi) from numpy's default_rng(seed)
    (the same seed gives the same signal everywhere), S chosen so the largest |u| on a grid of
    _MULTISINE_GRID points per period of the highest line is exactly 1. Returns (n, phi, S, bounds) with
    bounds = (peak, slope, curvature): upper bounds of sup |u|, sup |u'| and sup |u''| (per cycle of the base
    frequency, derivatives in 1/cycle and 1/cycle^2) over continuous phase, each the grid maximum plus
    h^2/8 sup|next derivative| (an extremum between grid points h apart is that close to one), so they are
    never below what any sampling of the signal reaches.
    """
    n = np.arange(first, last + 1, dtype=float)
    phi = np.random.default_rng(seed).uniform(0.0, 2 * np.pi, n.size)
    size = _MULTISINE_GRID * last
    size += size % 2
    spectrum = np.zeros(size // 2 + 1, complex)
    spectrum[first:last + 1] = -0.5j * size * np.exp(1j * phi)     # irfft of it: sum_k sin(2 pi n_k m / size + phi_k)
    w = 2j * np.pi * np.arange(spectrum.size)
    grid_max = [float(np.max(np.abs(np.fft.irfft(spectrum * w ** d, size)))) for d in range(3)]
    scale = grid_max[0]
    h2 = (1.0 / size) ** 2 / 8.0
    sums = [float(np.sum((2 * np.pi * n) ** d)) for d in range(5)]
    bounds = tuple((grid_max[d] + h2 * sums[d + 2]) / scale for d in range(3))
    return n, phi, scale, bounds


def multisine(phase, first: int, last: int, seed: int):
    """Unit random-phase multisine (see multisine_lines) at `phase` [cycles of the base frequency].

    Evaluated as Im(z^first P(z)) with z = exp(2 pi i phase) and P the polynomial of the lines' phasors (Horner:
    one complex multiply-add per line and sample, about ten times cheaper than a sine per line; rounding
    grows with the number of lines, ~1e-13 at 4096).
    """
    n, phi, scale, _ = multisine_lines(first, last, seed)
    coef = np.exp(1j * phi)
    flat = np.mod(np.asarray(phase, dtype=float), 1.0).ravel()
    out = np.empty(flat.size)
    for lo in range(0, flat.size, _MULTISINE_CHUNK):
        p = flat[lo:lo + _MULTISINE_CHUNK]
        z = np.exp(2j * np.pi * p)
        acc = np.full(p.size, coef[-1])
        for c in coef[-2::-1]:
            acc *= z
            acc += c
        out[lo:lo + p.size] = (np.exp(2j * np.pi * first * p) * acc).imag
    return (out / scale).reshape(np.shape(phase))


def envelope(phase, total_cycles: float, taper_cycles: float):
    """Taper envelope 0 -> 1 over the first taper_cycles and 1 -> 0 over the last, on phase in [0, total]."""
    if taper_cycles <= 0:
        return np.where((phase >= 0) & (phase <= total_cycles), 1.0, 0.0)
    return smoothstep(phase / taper_cycles) * smoothstep((total_cycles - phase) / taper_cycles)


def sweep_phase(t, f0: float, f1: float, taper_cycles: float, duration: float, log: bool):
    """Phase [cycles] of a sweep block at times t [s]: taper_cycles at f0, a linear or logarithmic sweep
    f0 -> f1 over `duration` s, then taper_cycles at f1. Returns (phase, total_cycles).
    """
    t_in = taper_cycles / f0
    tau = np.clip(t - t_in, 0.0, duration)
    if log and f1 != f0:
        r = np.log(f1 / f0)
        sweep = f0 * duration / r * np.expm1(tau * r / duration)
        sweep_total = f0 * duration / r * np.expm1(r)
    else:
        sweep = f0 * tau + 0.5 * (f1 - f0) * tau ** 2 / duration
        sweep_total = 0.5 * (f0 + f1) * duration
    phase = np.where(t < t_in, f0 * t, taper_cycles + sweep)
    after = t - t_in - duration
    phase = np.where(after > 0, taper_cycles + sweep_total + f1 * after, phase)
    return phase, 2 * taper_cycles + sweep_total


def sweep_frequency(t, f0: float, f1: float, taper_cycles: float, duration: float, log: bool):
    """Instantaneous frequency [Hz] of a sweep block at times t [s] (see sweep_phase)."""
    tau = np.clip(t - taper_cycles / f0, 0.0, duration) / duration
    return f0 * (f1 / f0) ** tau if log else f0 + (f1 - f0) * tau
