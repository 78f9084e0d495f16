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
"""
import numpy as np

PERIODIC = ('sine', 'triangle', 'square')
SWEEPS = ('sweep_lin', 'sweep_log')
WAVEFORMS = PERIODIC + SWEEPS + ('hold', 'ramp')
ALIASES = {'trapezoid': 'square', 'dwell': 'hold', 'sweep': 'sweep_lin', 'sine_sweep': 'sweep_lin'}


def smoothstep(u):
    """Raised cosine 0 -> 1 on u in [0, 1] (clipped outside): zero slope at both ends, so no velocity jump."""
    u = np.clip(u, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * u)


def triangle(phase):
    """Unit triangle starting at 0 going up, peak +1 at phase 0.25, -1 at 0.75 (slope 4 per cycle)."""
    return 4.0 * np.abs(np.mod(phase - 0.25, 1.0) - 0.5) - 1.0


def shape(waveform: str, phase, square_slope: float = 1.0):
    """Unit shape (-1..1) of a periodic waveform at `phase` [cycles].

    square_slope: for 'square' (trapezoid), the edge slope relative to the triangle's (>= 1); the edges then
    take 1/square_slope of a quarter period each, which realises a set transition rate.
    """
    if waveform in ('sine',) + SWEEPS:
        return np.sin(2.0 * np.pi * phase)
    if waveform == 'triangle':
        return triangle(phase)
    if waveform == 'square':
        return np.clip(square_slope * triangle(phase), -1.0, 1.0)
    raise ValueError(f'no periodic shape for waveform {waveform!r}')


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
