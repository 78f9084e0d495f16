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

"""Cycle cutting, the one implementation: upward mean crossings with hysteresis, streaming or batch.

* :class:`CycleCutter`: where the cycles of a displacement stream begin and end (chunks of any length).
* :func:`cut_cycles`: the same cut over a whole array (recordings, fitting).
* :class:`CycleDetector`: per-cycle harmonic properties of (x, force...) chunks, cut by a CycleCutter.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .harmonic import harmonic_properties


class Cycle(NamedTuple):
    """One cycle: samples [start, end) of the stream, and the mean crossings that bound it interpolated
    between samples (start_at, end_at, in samples; end_at - start_at is the period in samples).
    """

    start: int
    end: int
    start_at: float
    end_at: float


class CycleCutter:
    """Cuts a stream of displacement samples into cycles at upward crossings of its mean, with hysteresis.

    Schmitt trigger around the mean m with half band h = hysteresis * half_range: x must first go
    below m - h (arm), the boundary is the first sample at or above m after that, and it is only
    confirmed once x reaches m + h without falling back below m. Noise smaller than the band cannot
    create cycles. m and half_range are those of the last complete cycle (before the first one: of
    all data so far); nothing arms and no cycle is reported while the half range is below
    ``min_amplitude`` [m] - set it above the displacement noise, or noise at start-up (when the
    levels come from little data) can open false cycles. A cycle shorter than ``min_cycle_samples`` or
    with a half range below ``min_amplitude`` is not reported (and does not set the levels); a cycle
    longer than ``max_cycle_samples`` means the excitation was lost, and cutting starts over.
    ``levels`` = (mean, half_range) [m] known in advance replace the levels of the data so far until the
    first cycle completes (a whole recording knows them; a stream does not); with ``adapt=False`` they are
    kept for good instead of following each cycle.

    ``feed(x)`` returns the :class:`Cycle` s completed by the chunk. Chunking does not change the cut.
    """

    def __init__(self, hysteresis: float = 0.2, min_amplitude: float = 0.0, min_cycle_samples: int = 8,
                 max_cycle_samples: int = 2_000_000, levels: tuple | None = None, adapt: bool = True):
        if not 0 < hysteresis < 1:
            raise ValueError(f'hysteresis must be in (0, 1), got {hysteresis}')
        self.hysteresis, self.min_amplitude = float(hysteresis), float(min_amplitude)
        self.levels = None if levels is None else (float(levels[0]), float(levels[1]))
        if not adapt and self.levels is None:
            raise ValueError('adapt=False needs the levels')
        self.adapt = adapt
        self.min_cycle_samples, self.max_cycle_samples = int(min_cycle_samples), int(max_cycle_samples)
        self.reset()

    def reset(self):
        self._n = 0                      # samples consumed
        self._start = None               # absolute index of the running cycle's first sample (None: none yet)
        self._start_at = None            # ... and the crossing interpolated between samples
        self._x, self._x0 = [], 0        # samples from absolute index _x0 on (the running cycle, or a candidate)
        self._armed = False
        self._candidate = None           # absolute index of the pending upward mean crossing
        self._candidate_at = None        # ... and the crossing interpolated between samples
        self._prev = None                # the previous sample (across chunks)
        self._mean, self._half = self.levels or (None, None)   # levels of the last complete cycle
        self._lo, self._hi = np.inf, -np.inf

    @property
    def keep_from(self) -> int:
        """First absolute sample index a later cycle can still contain (older samples may be dropped)."""
        starts = [i for i in (self._start, self._candidate) if i is not None]
        return min(starts) if starts else self._n

    def feed(self, x) -> list:
        x = np.asarray(x, dtype=float).ravel()
        out, kept, n0 = [], self._x, self._n
        for i, xi in enumerate(x.tolist()):    # per-sample state machine; the per-cycle arithmetic is vectorised
            idx = n0 + i
            prev, self._prev = self._prev, xi
            kept.append(xi)
            if self._start is not None and idx - self._start >= self.max_cycle_samples:
                self._start = None                              # lost the excitation: start over
            if self._mean is None:
                self._lo, self._hi = min(self._lo, xi), max(self._hi, xi)
                m, half = 0.5 * (self._hi + self._lo), 0.5 * (self._hi - self._lo)
            else:
                m, half = self._mean, self._half
            if half > 0 and half >= self.min_amplitude:
                band = self.hysteresis * half
                if xi < m - band:
                    self._armed, self._candidate = True, None
                elif self._armed:
                    if xi < m:
                        self._candidate = None
                    elif self._candidate is None:
                        self._candidate = idx
                        # prev < m <= xi here: the crossing lies in (idx - 1, idx]
                        self._candidate_at = idx - (xi - m) / (xi - prev) if prev is not None and xi > prev \
                            else idx
                    if self._candidate is not None and xi >= m + band:
                        cycle = self._boundary(self._candidate, self._candidate_at)
                        if cycle is not None:
                            out.append(cycle)
                        self._armed, self._candidate = False, None
            if self._start is None:                             # no cycle running: keep only a candidate's
                self._drop_before(idx + 1 if self._candidate is None else self._candidate)
        self._n += x.size
        return out

    def _drop_before(self, index: int) -> None:
        if index > self._x0:
            del self._x[:index - self._x0]
            self._x0 = index

    def _boundary(self, at, at_interpolated):
        """Confirmed upward crossing at absolute sample ``at``: close the running cycle, start the next.
        Returns the closed cycle if it counts.
        """
        start, start_at = self._start, self._start_at
        self._start, self._start_at = at, at_interpolated
        cx = np.array(self._x[start - self._x0:at - self._x0]) if start is not None else None
        self._drop_before(at)
        if start is None or at - start < self.min_cycle_samples:   # the first crossing only starts a cycle
            return None
        half = 0.5 * float(cx.max() - cx.min())
        if half < self.min_amplitude:
            return None
        if self.adapt:
            self._mean, self._half = float(cx.mean()), half
        return Cycle(start, at, start_at, at_interpolated)


def cut_cycles(x, hysteresis: float = 0.2, min_amplitude: float = 0.0, min_cycle_samples: int = 8,
               adapt: bool = False) -> list:
    """The :class:`Cycle` s of a whole displacement array x [m], cut by a :class:`CycleCutter` whose levels are
    those of the whole array: its median, and the 99th percentile of the distance from it as half range.

    With ``adapt=False`` (one test block, one mean) the levels stay fixed, so the cut does not lag a
    change of amplitude by a cycle as a stream's must; ``adapt=True`` cuts as the online detector does, from
    the whole array's levels until the first cycle is complete.
    """
    x = np.asarray(x, dtype=float).ravel()
    if not x.size:
        return []
    median = float(np.median(x))
    levels = (median, float(np.percentile(np.abs(x - median), 99)))
    return CycleCutter(hysteresis, min_amplitude, min_cycle_samples, levels=levels, adapt=adapt).feed(x)


class CycleDetector:
    """Per-cycle harmonic properties of a stream of (x, force...) chunks, cut by a :class:`CycleCutter` on x.

    ``update(x, force, *more_forces)`` takes chunks of any length and returns a list of dicts, one
    per completed cycle: the :class:`HarmonicProperties` fields of ``force`` plus ``index`` (cycle
    count), ``start`` and ``end`` (absolute sample indices, end exclusive), ``period`` [s] and
    ``channels`` (the properties of every force channel, ``force`` first), and with two or more forces
    ``rms_difference`` [N], the RMS of ``force`` minus the second force over the cycle. The cut depends on x
    alone, so several forces measured against one displacement (e.g. measured and model) share one
    detector and its cycles. Chunking does not change the result. ``hysteresis``, ``min_amplitude``
    [m] and the cycle lengths [samples] are the cutter's.

    Why interpolated crossings: a cycle is cut at whole samples, so at 14 Hz and 1 kHz its length
    alternates between 71 and 72 samples, and a first-harmonic fit at 1/(71 dt) or 1/(72 dt) Hz
    misreads the amplitude by about +-1 %. The period and the fit frequency come from the mean
    crossings interpolated between the samples that straddle them instead, which removes that
    error (the fit itself is exact for any window length once the frequency is right).
    """

    def __init__(self, dt: float, hysteresis: float = 0.2, min_amplitude: float = 0.0,
                 min_cycle_samples: int = 8, max_cycle_samples: int = 2_000_000):
        if not dt > 0:
            raise ValueError(f'dt must be > 0 s, got {dt}')
        self.dt = float(dt)
        self.cutter = CycleCutter(hysteresis, min_amplitude, min_cycle_samples, max_cycle_samples)
        self.reset()

    @property
    def min_amplitude(self) -> float:
        return self.cutter.min_amplitude

    def reset(self):
        self.cutter.reset()
        self._buffers, self._first = None, 0     # x and force samples from absolute index _first on
        self._index = 0

    def update(self, x, force, *more_forces) -> list:
        x = np.asarray(x, dtype=float).ravel()
        forces = [np.asarray(f, dtype=float).ravel() for f in (force,) + more_forces]
        for f in forces:
            if f.shape != x.shape:
                raise ValueError(f'x and force chunks must have equal length, got {x.size} and {f.size}')
        if self._buffers is None:
            self._buffers = [np.zeros(0) for _ in range(1 + len(forces))]
        elif len(forces) + 1 != len(self._buffers):
            raise ValueError(f'{len(self._buffers) - 1} force channels so far, got {len(forces)}')
        self._buffers = [np.concatenate([b, c]) for b, c in zip(self._buffers, [x] + forces, strict=False)]
        out = []
        for cycle in self.cutter.feed(x):
            # the loop closes on the next cycle's first sample
            lo, hi = cycle.start - self._first, cycle.end + 1 - self._first
            x_cycle, forces = self._buffers[0][lo:hi], [b[lo:hi] for b in self._buffers[1:]]
            period = cycle.end_at - cycle.start_at          # [samples], within (k - 1, k + 1)
            channels = [harmonic_properties(x_cycle, f, self.dt, frequency=1.0 / (period * self.dt),
                                            whole_cycles=1).as_dict() for f in forces]
            d = dict(channels[0], channels=channels)
            if len(forces) > 1:   # e.g. measured - model: the residual a detector judges
                d['rms_difference'] = float(np.sqrt(np.mean((forces[0] - forces[1]) ** 2)))
            d.update(index=self._index, start=cycle.start, end=cycle.end, period=period * self.dt)
            self._index += 1
            out.append(d)
        keep = self.cutter.keep_from
        if keep > self._first:
            self._buffers = [b[keep - self._first:] for b in self._buffers]
            self._first = keep
        return out
