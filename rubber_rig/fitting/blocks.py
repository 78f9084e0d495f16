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

"""Split a recording into its test blocks and measure each block's steady cycles.

A block is one harmonic excitation (frequency, amplitude, mean). Boundaries come from, in order:
1. the recorded block index channel (the rig stamps every sample with its program block),
2. otherwise detection of steady periodic segments: cycles are cut as the online cycle metrics cut them
   (:func:`rubber_rig.analysis.cut_cycles`: upward mean crossings with hysteresis), and consecutive cycles
   with the same period and
   amplitude (within `tolerance`) form a segment. Taper-in/out cycles change amplitude and therefore
   fall outside the segments.
The recorded program (if any) then labels blocks with their nominal frequency and amplitude.

Inside a block, the first `settle_cycles` steady cycles are skipped (seed 000: Berg's friction loop
is steady after about three cycles) and the remaining whole cycles are analysed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..analysis import cut_cycles
from .metrics import window_properties


@dataclass
class BlockResult:
    """Measured properties of one block (SI units)."""

    index: int                 # block number in the recording (program order when known)
    start: int                 # first analysed sample
    stop: int                  # one past the last analysed sample
    cycles: int                # analysed cycles
    skipped_cycles: int        # settling cycles skipped
    frequency: float
    amplitude: float
    mean: float
    k_dyn: float
    loss_angle: float
    damping: float
    energy: float              # loop area per cycle [J]
    c_eq: float
    nominal_frequency: float | None = None
    nominal_amplitude: float | None = None
    segment: tuple = (0, 0)    # samples of the whole block (settling included)
    recording: str = ''

    def as_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


@dataclass
class SplitReport:
    blocks: list = field(default_factory=list)
    messages: list = field(default_factory=list)   # human-readable warnings, one per problem


def noise_level(x) -> float:
    """Standard deviation of the white noise on a smoothly varying signal ``x`` (shape (n,), its unit).

    Third differences cancel a smooth signal well at rig rates; their median absolute deviation, scaled to a
    sigma (1.4826) and divided by sqrt(20) (the variance gain of a third difference), estimates the noise.
    """
    d3 = np.diff(x, 3)
    if d3.size == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(d3 - np.median(d3))) / np.sqrt(20.0))


def noise_variance_uncertainty(x, segments: int = 16) -> float:
    """Relative standard uncertainty of noise_level(x)**2, from its scatter over ``segments`` equal parts of x.

    The misfit test compares the residual variance with this estimate of the noise variance, so the estimate's
    own uncertainty belongs in the test (a 1 % uncertain noise level is a 2 % uncertain variance). The scatter of
    the parts is measured, not assumed: it holds whatever the noise's distribution and correlation do to the
    MAD-based estimator. Returns inf when x is too short for ``segments`` parts of 64 samples.
    """
    x = np.asarray(x, float)
    n = x.size // segments
    if n < 64:
        return math.inf
    v = np.array([noise_level(x[k * n:(k + 1) * n]) ** 2 for k in range(segments)])
    mean = float(v.mean())
    if mean <= 0:
        return math.inf
    return float(v.std(ddof=1) / math.sqrt(segments) / mean)


def harmonic_sigma(noise, n_samples, amplitude, frequency):
    """1-sigma of K_dyn [N/m] and of C_eq [N s/m] measured over ``n_samples`` samples of a block of
    displacement ``amplitude`` [m] at ``frequency`` [Hz] with white load-cell noise ``noise`` [N] (broadcasts).

    The first harmonic of N samples of white noise sigma has a sigma of sigma sqrt(2/N) per component;
    K_dyn = |F1| / A and C_eq = Im F1 / (omega A).
    """
    s = np.asarray(noise, float) * np.sqrt(2.0 / np.maximum(np.asarray(n_samples, float), 1.0))
    amplitude = np.asarray(amplitude, float)
    return s / amplitude, s / (2 * np.pi * np.asarray(frequency, float) * amplitude)


def _cycles(x) -> list:
    """The cycles of x, cut as everywhere else (:func:`rubber_rig.analysis.cut_cycles`) about the levels of the
    whole segment. The hysteresis band is 2 % of the largest amplitude but at least 5 noise sigmas, so that
    small-amplitude blocks of a recording without block index still cross it, and motion within 5 noise
    sigmas of standing still makes no cycle.
    """
    x = np.asarray(x, float)
    if x.size < 4:
        return []
    noise = noise_level(x)
    half = float(np.percentile(np.abs(x - np.median(x)), 99))
    if not half > 5.0 * noise:
        return []
    return cut_cycles(x, hysteresis=max(0.02, 5.0 * noise / half), min_amplitude=5.0 * noise)


def _steady_runs(x, cycles, tolerance):
    """Runs of consecutive, adjoining cycles with the same period and amplitude: list of (c_first, c_last)."""
    n = len(cycles)
    if n < 1:
        return []
    periods = np.array([c.end_at - c.start_at for c in cycles])
    amps = np.array([0.5 * np.ptp(x[c.start:c.end]) for c in cycles])
    means = np.array([np.mean(x[c.start:c.end]) for c in cycles])
    runs = []
    start = 0
    for c in range(1, n + 1):
        if c < n:
            p_ref = np.median(periods[start:c])
            a_ref = np.median(amps[start:c])
            same = (cycles[c].start == cycles[c - 1].end
                    and abs(periods[c] - p_ref) <= tolerance * p_ref + 1.5
                    and abs(amps[c] - a_ref) <= tolerance * a_ref
                    and abs(means[c] - np.median(means[start:c])) <= tolerance * a_ref)
            if same:
                continue
        runs.append((start, c - 1))
        start = c
    return runs


def _nominal(program_block):
    if not program_block:
        return None, None
    f = program_block.get('frequency')
    a = program_block.get('amplitude')
    return (float(f) if f is not None else None), (float(a) if a is not None else None)


def split_blocks(displacement, force, dt, block_index=None, program_blocks=None,
                 settle_cycles: int = 3, min_cycles: int = 2, tolerance: float = 0.03,
                 recording: str = '') -> SplitReport:
    """Find the blocks of a recording and measure their steady cycles.

    displacement, force: arrays [m], [N] sampled every `dt` s. block_index: optional per-sample
    program block number (negative = between blocks). program_blocks: optional list of dicts with
    at least 'frequency' [Hz] and 'amplitude' [m] (e.g. the recorded test program's sine blocks), used
    to label blocks and to report blocks that are missing from the recording.
    """
    where = f'{recording}: ' if recording else ''   # message prefix naming the recording
    x = np.asarray(displacement, float)
    f = np.asarray(force, float)
    if x.shape != f.shape:
        raise ValueError(f'displacement ({x.size} samples) and force ({f.size} samples) differ in length')
    report = SplitReport()
    finite = np.isfinite(x) & np.isfinite(f)
    expected = list(program_blocks or [])
    seen_labels = set()
    counter = 0      # blocks found by detection (no block index): numbered in order
    for label, s, e in _labelled_segments(block_index, x.size):
        if label is not None and 0 <= label < len(expected) and \
                expected[label].get('waveform') not in (None, 'sine'):
            seen_labels.add(label)
            continue   # holds, ramps, triangles: no harmonic steady state to measure
        s, e = _longest_finite(finite, s, e, report, f'{where}block {label if label is not None else "?"}')
        cycles = _cycles(x[s:e])
        runs = _steady_runs(x[s:e], cycles, tolerance)
        if label is not None:
            runs = [max(runs, key=lambda r: r[1] - r[0])] if runs else []
        for c0, c1 in runs:
            if label is None and c1 - c0 + 1 < 2:
                continue   # detection: single odd cycles are tapers / transitions, not blocks
            lab = label if label is not None else counter
            nominal = expected[lab] if (label is not None and 0 <= lab < len(expected)) else None
            block = _measure_run(x, f, dt, s, cycles, (c0, c1), lab, nominal, settle_cycles, min_cycles, recording,
                                 report, where)
            if block is not None:
                report.blocks.append(block)
            seen_labels.add(lab)
            if label is None:
                counter += 1
    if block_index is not None and expected:
        _report_missing(expected, seen_labels, report, where)
    if not report.blocks:
        report.messages.append(f'{where}no usable steady block found')
    return report


def _labelled_segments(block_index, n: int) -> list:
    """(program block number, start, stop) of each stretch of one block number >= 0; the whole record as one
    unlabelled segment (None, 0, n) when there is no block index.
    """
    if block_index is None:
        return [(None, 0, n)]
    bi = np.asarray(block_index)
    change = np.flatnonzero(np.diff(bi) != 0) + 1
    bounds = np.concatenate([[0], change, [bi.size]])
    return [(int(bi[s]), int(s), int(e)) for s, e in zip(bounds[:-1], bounds[1:], strict=False) if bi[s] >= 0]


def _longest_finite(finite, s: int, e: int, report: SplitReport, what: str) -> tuple:
    """(start, stop) of the longest stretch of finite samples in s..e; says in `report` what was lost."""
    seg_ok = finite[s:e]
    if seg_ok.all():
        return s, e
    bad = np.flatnonzero(~seg_ok)
    report.messages.append(f'{what}: {bad.size} samples with missing values (NaN); only the longest complete '
                           'stretch is analysed')
    edges = np.concatenate([[-1], bad, [e - s]])
    k = int(np.argmax(np.diff(edges)))
    return s + edges[k] + 1, s + edges[k + 1]


def _measure_run(x, f, dt, s, cycles, run, lab, nominal, settle_cycles, min_cycles, recording, report, where):
    """BlockResult of the steady cycles run = (c0, c1) of the segment starting at sample s, the first
    `settle_cycles` skipped; None (and a message in `report`) when too few cycles are steady.
    """
    c0, c1 = run
    n_steady = c1 - c0 + 1
    nf, na = _nominal(nominal)
    if n_steady < settle_cycles + min_cycles:
        desc = f'{nf:g} Hz, {na * 1e3:g} mm' if nf and na else f'{n_steady} cycles'
        report.messages.append(
            f'{where}block {lab} ({desc}): only {n_steady} steady cycles, need '
            f'{settle_cycles + min_cycles} ({settle_cycles} settling + {min_cycles} analysed); skipped')
        return None
    first, last = cycles[c0 + settle_cycles], cycles[c1]
    a0, a1 = s + first.start, s + last.end
    ncyc = n_steady - settle_cycles
    freq = ncyc / ((last.end_at - first.start_at) * dt)
    if nf and abs(freq / nf - 1) < 0.005:
        freq = nf      # the program's frequency is exact (setpoints come from the sample index)
    props = window_properties(x, f, dt, a0, a1, freq)
    return BlockResult(
        index=int(lab), start=int(a0), stop=int(a1), cycles=int(ncyc),
        skipped_cycles=int(settle_cycles), frequency=float(props['frequency']),
        amplitude=float(props['amplitude']), mean=float(props['mean']),
        k_dyn=float(props['k_dyn']), loss_angle=float(props['loss_angle']),
        damping=float(props['damping']), energy=float(props['energy_loop']),
        c_eq=float(props['c_eq']), nominal_frequency=nf, nominal_amplitude=na,
        segment=(int(s + cycles[c0].start), int(s + last.end)), recording=recording)


def _report_missing(expected: list, seen_labels: set, report: SplitReport, where: str) -> None:
    """Say which program blocks the recording lacks: a truncated tail, or blocks missing inside."""
    missing = [i for i in range(len(expected)) if i not in seen_labels]
    if not missing:
        return
    last = max(seen_labels) if seen_labels else -1
    tail = [i for i in missing if i > last]
    if tail:
        report.messages.append(f'{where}recording ends before block {tail[0]} of {len(expected)} '
                               f'(truncated): blocks {tail[0]}-{len(expected) - 1} missing')
    inner = [i for i in missing if i <= last]
    if inner:
        report.messages.append(f'{where}blocks {inner} of the program are not in the recording')
