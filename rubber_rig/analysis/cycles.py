"""Streaming cycle detection: per-cycle harmonic properties as chunks of (x, force) arrive."""
from __future__ import annotations

import numpy as np

from .harmonic import harmonic_properties


class CycleDetector:
    """Splits a stream into cycles at upward crossings of the running mean of x, with hysteresis.

    A crossing counts only after x has been below ``mean - hysteresis * half_range`` since the last
    one, so noise around the mean (smaller than that band) cannot create false cycles. The mean and
    half range are those of the last complete cycle (before the first cycle: of all data so far).
    ``update(x, force)`` takes chunks of any length and returns a list of dicts, one per completed
    cycle: the :class:`HarmonicProperties` fields plus ``index`` (cycle count), ``start`` and
    ``end`` (absolute sample indices, end exclusive) and ``period`` [s].

    dt [s]; hysteresis [-] fraction of the half range; min_cycle_samples, max_cycle_samples bound
    a cycle's length (longer stretches are dropped and detection restarts).
    """

    def __init__(self, dt: float, hysteresis: float = 0.2, min_cycle_samples: int = 8,
                 max_cycle_samples: int = 2_000_000):
        if not dt > 0:
            raise ValueError(f'dt must be > 0 s, got {dt}')
        if not 0 < hysteresis < 1:
            raise ValueError(f'hysteresis must be in (0, 1), got {hysteresis}')
        self.dt, self.hysteresis = float(dt), float(hysteresis)
        self.min_cycle_samples, self.max_cycle_samples = int(min_cycle_samples), int(max_cycle_samples)
        self.reset()

    def reset(self):
        self._n = 0                     # samples consumed
        self._start = None              # absolute index of the current cycle's first sample
        self._bx, self._bf = [], []     # current cycle's samples (chunks)
        self._armed = False
        self._mean = None
        self._half = None
        self._lo, self._hi, self._sum, self._cnt = np.inf, -np.inf, 0.0, 0
        self._index = 0
        self._prev = None               # last sample (x, f) before the current chunk

    def _levels(self):
        if self._mean is not None:
            return self._mean, self._half
        if self._cnt == 0 or self._hi <= self._lo:
            return None, None
        return 0.5 * (self._hi + self._lo), 0.5 * (self._hi - self._lo)

    def update(self, x, force) -> list:
        x = np.asarray(x, dtype=float).ravel()
        force = np.asarray(force, dtype=float).ravel()
        if x.shape != force.shape:
            raise ValueError(f'x and force chunks must have equal length, got {x.size} and {force.size}')
        out = []
        for i in range(x.size):    # per-sample state machine; the arithmetic per cycle is vectorised
            xi = float(x[i])
            if self._mean is None:
                self._lo, self._hi = min(self._lo, xi), max(self._hi, xi)
                self._sum += xi
                self._cnt += 1
            mean, half = self._levels()
            if mean is not None:
                if xi < mean - self.hysteresis * half:
                    self._armed = True
                elif self._armed and xi >= mean:
                    self._armed = False
                    out.extend(self._boundary(self._n + i))
            if self._start is not None:
                self._bx.append(xi)
                self._bf.append(float(force[i]))
                if len(self._bx) > self.max_cycle_samples:
                    self._start, self._bx, self._bf = None, [], []
        self._n += x.size
        return out

    def _boundary(self, index):
        """Upward crossing at absolute sample ``index``: close the running cycle, start the next."""
        results = []
        if self._start is not None and len(self._bx) >= self.min_cycle_samples:
            cx = np.array(self._bx)
            cf = np.array(self._bf)
            n = cx.size
            # close the loop with the crossing sample itself (it starts the next cycle)
            results.append(self._metrics(cx, cf, n))
            self._mean = float(cx.mean())
            self._half = 0.5 * float(cx.max() - cx.min())
        self._start = index
        self._bx, self._bf = [], []
        return results

    def _metrics(self, cx, cf, n):
        # the cycle is samples [start, index); fold in the first sample of the next cycle when it
        # arrives is not possible here, so evaluate over n samples with the loop closed on its start
        xs = np.append(cx, cx[0])
        fs = np.append(cf, cf[0])
        props = harmonic_properties(xs, fs, self.dt, frequency=1.0 / (n * self.dt))
        d = props.as_dict()
        d.update(index=self._index, start=self._start, end=self._start + n, period=n * self.dt)
        self._index += 1
        return d
