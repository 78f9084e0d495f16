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

"""The white noise on a recorded channel, with the excitation's harmonics removed first: right on every band.

Every misfit test divides a residual variance by a noise variance, so the noise estimate sets the test's
sensitivity. `blocks.noise_level` (the MAD of third differences) cancels a smooth signal only while the
signal's third difference is small beside the noise: a sine of amplitude F at frequency f leaves
(2 sin(pi f dt))^3 F in it, 3 % of F at 50 Hz sampled at 1 kHz. On 20-50 Hz blocks a 20 N load cell came out
21.5-22.4 N and a 0.2 um transducer 0.36 um, so a correct model showed chi^2/dof 0.83-0.93 and a missing
branch could hide in the gap.

:func:`band_noise` removes what is periodic at the excitation first: in each analysed block window (whole
steady cycles at a known frequency f; up to MAX_STRETCHES stretches of STRETCH samples) the signal is
projected on a mean, a linear drift and cos/sin of k 2 pi f t for k = 1 .. K (K harmonics up to 0.45 of the
sample rate, at most ``MAX_HARMONICS``), and the
third differences of what is left give the noise by their median absolute deviation, as before. What the
projection takes away from white noise is known exactly (the third differences of the projection's
orthonormal basis Q: E||D r||^2 = sigma^2 (20 (n - 3) - ||D Q||_F^2)), and the estimate is corrected for it.
The estimate's own uncertainty is the measured scatter of the same estimator over ``SEGMENTS`` parts of the
pooled differences (the misfit test carries it, misfit.misfit_test).

Checked against the truth (test/test_fitting_noise.py, and the closing figures of the CHANGELOG) on simulated
records from 0.05 Hz to 100 Hz at 1 kHz and 10 kHz.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MAD_TO_SIGMA = 1.4826       # the MAD of a normal variable times this is its sigma
D3_GAIN = 20.0              # variance gain of a third difference of white noise (1 + 9 + 9 + 1)
MAX_HARMONICS = 20          # harmonics of the excitation removed per stretch (above them the third differences
#                             leave friction corners' harmonics far below the noise; tested down to 0.05 Hz)
STRETCH = 4096              # samples per projected stretch (cost ~ STRETCH (2 MAX_HARMONICS)^2)
MAX_STRETCHES = 4           # stretches per block, spread over its analysed window
SEGMENTS = 16               # parts for the estimate's own scatter
OUTLIER_Z = 6.0             # |residual| beyond this many sigmas is an outlier (white noise: 2e-9 of the samples)


@dataclass(frozen=True)
class NoiseEstimate:
    """White-noise level of one channel of one recording.

    sigma: standard deviation [the channel's unit]; variance_u: relative standard uncertainty of sigma**2
    (inf when too few samples to say); samples: third differences used; method: 'harmonics_removed' (block
    windows at their excitation frequency) or 'third_differences' (the whole record, no block known).
    """

    sigma: float
    variance_u: float
    samples: int
    method: str
    outliers: int = 0             # residual samples beyond OUTLIER_Z sigma (diagnoses.outlier_sentence)
    examined: int = 0             # residual samples examined for outliers
    largest: float = 0.0          # the largest |residual| [sigma]
    largest_at: int = -1          # its sample index in the record (-1: none examined)

    def as_dict(self) -> dict:
        return {'sigma': self.sigma, 'variance_u': self.variance_u, 'samples': self.samples, 'method': self.method,
                'outliers': self.outliers, 'examined': self.examined, 'largest': self.largest,
                'largest_at': self.largest_at}


def _mad_sigma(d) -> float:
    return float(MAD_TO_SIGMA * np.median(np.abs(d - np.median(d)))) if d.size else 0.0


def harmonic_residual(x, dt: float, frequency: float, harmonics: int | None = None) -> tuple:
    """(residual, ||D Q||_F^2): ``x`` (shape (n,)) less its least-squares projection on a mean, a linear drift and
    cos/sin of the first ``harmonics`` multiples of ``frequency`` [Hz] (default: up to 0.45 / dt, at most
    MAX_HARMONICS), sampled every ``dt`` s; and the squared Frobenius norm of the third differences of the
    projection's orthonormal basis (what the projection removes from white noise's third differences, in units
    of its variance).
    """
    x = np.asarray(x, float)
    n = x.size
    t = (np.arange(n) - 0.5 * (n - 1)) * dt
    k_max = int(0.45 / (frequency * dt)) if frequency > 0 else 0
    k_max = min(MAX_HARMONICS if harmonics is None else harmonics, k_max)
    cols = [np.ones(n), t / max(t[-1], dt)]
    if k_max:
        step = np.exp(2j * math.pi * frequency * t)
        power = step.copy()
        for _ in range(k_max):          # cos/sin of k w t by repeated multiplication (no trigonometry per k)
            cols += [power.real.copy(), power.imag.copy()]
            power *= step
    q = _orthonormal(cols)
    residual = x.copy()
    removed = 0.0
    for col in q:
        residual -= col * float(np.sum(col * residual))
        d = np.diff(col, 3)
        removed += float(np.sum(d * d))
    return residual, removed


def _orthonormal(columns) -> list:
    """An orthonormal basis (list of arrays) of the span of ``columns``: modified Gram-Schmidt, each column
    orthogonalised twice (stable to rounding), columns that add less than 1e-8 of their norm dropped (in a window
    shorter than a cycle the harmonics are nearly dependent; what they share is removed once).

    Elementwise numpy, no LAPACK: a multithreaded BLAS spends several times the CPU of one thread on these small
    problems when the machine is busy (measured: QR of 4096 x 42, 10 x the CPU time on a loaded 2-core machine).
    """
    basis = []
    for c in columns:
        v = np.array(c, float)
        norm0 = math.sqrt(float(np.sum(v * v)))
        if norm0 == 0:
            continue
        for _ in range(2):
            for q in basis:
                v -= q * float(np.sum(q * v))
        norm = math.sqrt(float(np.sum(v * v)))
        if norm > 1e-8 * norm0:
            basis.append(v / norm)
    return basis


def band_noise(x, dt: float, windows) -> NoiseEstimate:
    """White-noise level of ``x`` (shape (n,), any unit) from the block ``windows`` [(start, stop, frequency
    [Hz])], with each block's excitation harmonics removed (module docstring). Without windows: the third
    differences of the whole record (`blocks.noise_level`'s estimator).
    """
    x = np.asarray(x, float)
    parts, removed, total, residuals = [], 0.0, 0, []
    for start, stop, frequency in windows or ():
        start, stop = int(max(start, 0)), int(min(stop, x.size))
        if stop - start < 16 or not frequency or not np.isfinite(frequency):
            continue
        count = min(MAX_STRETCHES, max(1, (stop - start) // STRETCH))
        length = min(STRETCH, stop - start)
        for a in np.linspace(start, stop - length, count).astype(int):
            seg = x[a:a + length]
            if not np.isfinite(seg).all():
                continue
            residual, dq2 = harmonic_residual(seg, dt, float(frequency))
            residuals.append((a, residual))
            d3 = np.diff(residual, 3)
            parts.append(d3)
            removed += dq2
            total += d3.size
    if not parts:
        d3 = np.diff(x[np.isfinite(x)], 3)
        return NoiseEstimate(_mad_sigma(d3) / math.sqrt(D3_GAIN), _segment_u(d3, 1.0), int(d3.size),
                             'third_differences')
    d3 = np.concatenate(parts)
    # the projection took ||D Q||^2 noise variances out of the third differences' expected sum of squares
    keep = max(1.0 - removed / (D3_GAIN * total), 0.5)
    scale = 1.0 / math.sqrt(D3_GAIN * keep)
    sigma = _mad_sigma(d3) * scale
    count, examined, largest, at = 0, 0, 0.0, -1
    if sigma > 0:
        for a, residual in residuals:
            z = np.abs(residual) / sigma
            count += int(np.count_nonzero(z > OUTLIER_Z))
            examined += z.size
            k = int(np.argmax(z))
            if z[k] > largest:
                largest, at = float(z[k]), a + k
    return NoiseEstimate(sigma, _segment_u(d3, scale), int(d3.size), 'harmonics_removed', count, examined, largest,
                         at)


def _segment_u(d3, scale: float) -> float:
    """Relative standard uncertainty of the variance estimate, from its scatter over SEGMENTS parts of ``d3``."""
    n = d3.size // SEGMENTS
    if n < 64:
        return math.inf
    v = np.array([(_mad_sigma(d3[k * n:(k + 1) * n]) * scale) ** 2 for k in range(SEGMENTS)])
    mean = float(v.mean())
    if mean <= 0:
        return math.inf
    return float(v.std(ddof=1) / math.sqrt(SEGMENTS) / mean)


def block_windows(blocks, recording: str | None = None) -> list:
    """[(start, stop, frequency)] of the analysed windows of ``blocks`` (BlockResult) of one recording."""
    return [(b.start, b.stop, b.frequency) for b in blocks
            if recording is None or b.recording == recording]


def run_noise(run, blocks) -> dict:
    """{'force': NoiseEstimate, 'displacement': NoiseEstimate} of ``run`` (RunData) over its ``blocks``."""
    windows = block_windows(blocks, run.name)
    return {'force': band_noise(run.force, run.dt, windows),
            'displacement': band_noise(run.displacement, run.dt, windows)}
