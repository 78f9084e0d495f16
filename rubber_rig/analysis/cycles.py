"""Streaming cycle detection: per-cycle harmonic properties as chunks of (x, force...) arrive."""
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

    ``update(x, force, *more_forces)`` takes chunks of any length and returns a list of dicts, one
    per completed cycle: the :class:`HarmonicProperties` fields of ``force`` plus ``index`` (cycle
    count), ``start`` and ``end`` (absolute sample indices, end exclusive), ``period`` [s] and
    ``channels`` (the properties of every force channel, ``force`` first). The cut depends on x
    alone, so several forces measured against one displacement (e.g. measured and model) share one
    detector and its cycles. Chunking does not change the result.

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
        self._bx = []                    # samples of x since _start
        self._bf = None                  # ... and of every force channel (a list per channel)
        self._armed = False
        self._candidate = None           # absolute index of the pending upward mean crossing
        self._candidate_at = None        # ... and the crossing interpolated between samples
        self._start_at = None            # interpolated crossing that opened the running cycle
        self._prev = None                # the previous sample (across chunks)
        self._mean = self._half = None   # levels of the last complete cycle
        self._lo, self._hi = np.inf, -np.inf
        self._index = 0

    def update(self, x, force, *more_forces) -> list:
        x = np.asarray(x, dtype=float).ravel()
        forces = [np.asarray(f, dtype=float).ravel() for f in (force,) + more_forces]
        for f in forces:
            if f.shape != x.shape:
                raise ValueError(f'x and force chunks must have equal length, got {x.size} and {f.size}')
        if self._bf is None:
            self._bf = [[] for _ in forces]
        elif len(forces) != len(self._bf):
            raise ValueError(f'{len(self._bf)} force channels so far, got {len(forces)}')
        out = []
        for i in range(x.size):     # per-sample state machine; the per-cycle arithmetic is vectorised
            xi, idx = float(x[i]), self._n + i
            prev, self._prev = self._prev, xi
            if self._start is None:                             # the first sample after reset()
                self._start = idx
            self._bx.append(xi)
            for buf, f in zip(self._bf, forces):
                buf.append(float(f[i]))
            if len(self._bx) > self.max_cycle_samples:          # lost the excitation: start over
                self._start, self._first = idx + 1, True
                self._bx, self._bf = [], [[] for _ in forces]
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
            self._bx, self._bf = self._bx[k:], [buf[k:] for buf in self._bf]
            self._start, self._start_at, self._first = at, at_interpolated, False
            return results
        # close the loop on the next cycle's first sample
        xs = np.array(self._bx[:k + 1])
        fs = [np.array(buf[:k + 1]) for buf in self._bf]
        self._bx, self._bf = self._bx[k:], [buf[k:] for buf in self._bf]
        start, self._start = self._start, at
        period = at_interpolated - self._start_at   # [samples], within (k - 1, k + 1)
        self._start_at = at_interpolated
        if k >= self.min_cycle_samples:
            cx = xs[:-1]
            half = 0.5 * float(cx.max() - cx.min())
            if half >= self.min_amplitude:
                channels = [harmonic_properties(xs, f, self.dt, frequency=1.0 / (period * self.dt),
                                                whole_cycles=1).as_dict() for f in fs]
                d = dict(channels[0], channels=channels)
                d.update(index=self._index, start=start, end=at, period=period * self.dt)
                self._index += 1
                results.append(d)
                self._mean, self._half = float(cx.mean()), half
        return results
