"""Streaming cycle detection: per-cycle harmonic properties as chunks of (x, force) arrive."""
from __future__ import annotations

import numpy as np

from .harmonic import harmonic_properties


class CycleDetector:
    """Splits a stream into cycles at upward crossings of the running mean of x, with hysteresis.

    Schmitt trigger around the mean m with half band h = hysteresis * half_range: x must first go
    below m - h (arm), the boundary is the first sample at or above m after that, and it is only
    confirmed once x reaches m + h without falling back below m. Noise smaller than the band cannot
    create cycles. m and half_range are those of the last complete cycle (before the first one: of
    all data so far); nothing arms and no cycle is reported while the half range is below
    ``min_amplitude`` [m] - set it above the displacement noise, or noise at start-up (when the
    levels come from little data) can open false cycles.

    ``update(x, force)`` takes chunks of any length and returns a list of dicts, one per completed
    cycle: the :class:`HarmonicProperties` fields plus ``index`` (cycle count), ``start`` and
    ``end`` (absolute sample indices, end exclusive) and ``period`` [s]. Chunking does not change
    the result.

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
        if not 0 < hysteresis < 1:
            raise ValueError(f'hysteresis must be in (0, 1), got {hysteresis}')
        self.dt, self.hysteresis, self.min_amplitude = float(dt), float(hysteresis), float(min_amplitude)
        self.min_cycle_samples, self.max_cycle_samples = int(min_cycle_samples), int(max_cycle_samples)
        self.reset()

    def reset(self):
        self._n = 0                      # samples consumed
        self._start = None               # absolute index of the buffer's first sample
        self._first = True               # no cycle started yet
        self._bx, self._bf = [], []      # samples since _start
        self._armed = False
        self._candidate = None           # absolute index of the pending upward mean crossing
        self._candidate_at = None        # ... and the crossing interpolated between samples
        self._start_at = None            # interpolated crossing that opened the running cycle
        self._prev = None                # the previous sample (across chunks)
        self._mean = self._half = None   # levels of the last complete cycle
        self._lo, self._hi = np.inf, -np.inf
        self._index = 0

    def update(self, x, force) -> list:
        x = np.asarray(x, dtype=float).ravel()
        force = np.asarray(force, dtype=float).ravel()
        if x.shape != force.shape:
            raise ValueError(f'x and force chunks must have equal length, got {x.size} and {force.size}')
        out = []
        for i in range(x.size):     # per-sample state machine; the per-cycle arithmetic is vectorised
            xi, idx = float(x[i]), self._n + i
            prev, self._prev = self._prev, xi
            if self._start is None and self._candidate is None:
                self._start, self._bx, self._bf = idx, [], []   # nothing before a crossing is kept
                self._first = True
            self._bx.append(xi)
            self._bf.append(float(force[i]))
            if len(self._bx) > self.max_cycle_samples:          # lost the excitation: start over
                self._start, self._bx, self._bf, self._first = idx + 1, [], [], True
            if self._mean is None:
                self._lo, self._hi = min(self._lo, xi), max(self._hi, xi)
                m, half = 0.5 * (self._hi + self._lo), 0.5 * (self._hi - self._lo)
            else:
                m, half = self._mean, self._half
            if not half > 0 or half < self.min_amplitude:
                continue
            band = self.hysteresis * half
            if xi < m - band:
                self._armed, self._candidate = True, None
            elif self._armed:
                if xi < m:
                    self._candidate = None
                elif self._candidate is None:
                    self._candidate = idx
                    # prev < m <= xi here: the crossing lies in (idx - 1, idx]
                    self._candidate_at = idx - (xi - m) / (xi - prev) if prev is not None and xi > prev else idx
                if self._candidate is not None and xi >= m + band:
                    out.extend(self._boundary(self._candidate, self._candidate_at))
                    self._armed, self._candidate = False, None
        self._n += x.size
        return out

    def _boundary(self, at, at_interpolated):
        """Confirmed upward crossing at absolute sample ``at``: close the running cycle, start the next."""
        results = []
        k = at - self._start
        if self._first:              # the first crossing only starts the first cycle
            self._bx, self._bf, self._start, self._first = self._bx[k:], self._bf[k:], at, False
            self._start_at = at_interpolated
            return results
        cx, cf = np.array(self._bx[:k]), np.array(self._bf[:k])
        self._bx, self._bf = self._bx[k:], self._bf[k:]
        start, self._start = self._start, at
        start_at, self._start_at = self._start_at, at_interpolated
        period = at_interpolated - start_at if start_at is not None else float(k)   # [samples]
        if not abs(period - k) < 1.0:    # cannot happen with prev < m <= x; keep the cut's length if it does
            period = float(k)
        if k >= self.min_cycle_samples:
            half = 0.5 * float(cx.max() - cx.min())
            if half >= self.min_amplitude:
                # close the loop on the next cycle's first sample
                xs = np.append(cx, self._bx[0])
                fs = np.append(cf, self._bf[0])
                props = harmonic_properties(xs, fs, self.dt, frequency=1.0 / (period * self.dt), whole_cycles=1)
                d = props.as_dict()
                d.update(index=self._index, start=start, end=at, period=period * self.dt)
                self._index += 1
                results.append(d)
                self._mean, self._half = float(cx.mean()), half
        return results
