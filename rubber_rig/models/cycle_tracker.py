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


"""The operating point of a moving element, sample by sample: amplitude A [m], mean x0 [m] and frequency f [Hz]
estimated from the last two velocity reversals (seed 004 never says how they are known while the pad moves),
with the same reversal deadband as Berg's element (:mod:`.friction`), so measured noise does not make reversals.
Streaming and batch use the same arithmetic, so they agree exactly.
"""
from __future__ import annotations

import math

import numpy as np

from .friction import check_reversal_threshold
from .trend import check_finite, check_positive

# [m] floor of every amplitude estimate: the ellipse divides by A, and before the first motion A would be 0
AMPLITUDE_FLOOR = 1e-12

# batch tracker: after a stretch between direction changes shorter than _DENSE/2 samples, the next one runs sample
# by sample (noise with a zero deadband reverses every few samples, and numpy calls on a few samples cost more)
_DENSE = 96


class CycleTracker:
    """Operating point (A [m], x0 [m], f [Hz]) of a cyclic displacement from its velocity reversals.

    At each accepted reversal the last two reversal points (x_r1, t_r1), (x_r2, t_r2) give

        A = |x_r1 - x_r2| / 2,   x0 = (x_r1 + x_r2) / 2,   f = 1 / (2 (t_r1 - t_r2)),

    exact for seed 004's excitation x = x0 + A sin(w t) (Table 1) up to the sampling of its extremes. A reversal is
    a sign change of the displacement increment (a zero increment keeps the direction), with the deadband
    d = ``reversal_threshold`` [m] of Berg's element (:mod:`.friction`): with d > 0 a reversal is accepted once x
    has moved more than d back from the extreme x_ext reached since the last one, so noise smaller than d makes no
    reversals. The reversal point x_r is that extreme; its time t_r is where x crossed x_ext -+ d on the way back,
    interpolated linearly between the two samples around the crossing. With d = 0 that is the extreme's sample time
    (the increment's sign change); with d > 0 it lags each extreme of a cycle by the same time where the cycle is
    symmetric about its extremes (a sine), so t_r1 - t_r2 is still the half period, and measured where x moves
    fast it is neither quantised to dt nor moved by the noise at the flat extreme the way the extreme's own sample
    time is (with 0.2 um noise on a 0.5 mm, 4 Hz sine at 1 kHz, the noisy extreme wanders by +-1.5 samples).
    The first direction is fixed once x leaves (x_start - d, x_start + d), x_start = ``reset``'s x0.

    Before two reversals have been seen the estimates are the defaults ``amplitude``, ``center``, ``frequency``
    where given, else A = running max |x - x_start|, x0 = x_start, f = NaN (unknown). A is floored at
    :data:`AMPLITUDE_FLOOR` so it is always > 0.

    Parameters
    ----------
    dt : float
        Sample period [s].
    amplitude, center, frequency : float or None
        Defaults A [m] (> 0), x0 [m], f [Hz] (> 0) until two reversals have been seen.
    reversal_threshold : float
        Reversal deadband d [m] (>= 0; 0 is every sign change of the increment).
    """

    def __init__(self, dt: float, amplitude=None, center=None, frequency=None, reversal_threshold: float = 0.0):
        self.dt = check_positive('dt', dt, required=True)
        self.default_amplitude = check_positive('amplitude', amplitude)
        self.default_center = check_finite('center', center)
        self.default_frequency = check_positive('frequency', frequency)
        self.reversal_threshold = check_reversal_threshold(float(reversal_threshold), reversal_threshold)
        self.reset()

    # n = index of the next sample, x_prev the last sample; direction 0 = none yet; x_ext = extreme of the current
    # stretch; amax = running max |x - x_start|; n_rev = reversals so far, (x_r1, t_r1) the last one and (x_r2,
    # t_r2) the one before (t in samples, fractional)
    _STATE = ('n', 'x_prev', 'x_start', 'direction', 'x_ext', 'amax', 'n_rev', 'x_r1', 't_r1', 'x_r2', 't_r2')
    _INTS = ('n', 'direction', 'n_rev')

    def reset(self, x0: float = 0.0):
        """No history; at rest at x0 [m] (the start point x_start)."""
        x0 = float(x0)
        self.n, self.x_prev, self.x_start, self.direction, self.x_ext, self.amax = 0, x0, x0, 0, x0, 0.0
        self.n_rev, self.x_r1, self.t_r1, self.x_r2, self.t_r2 = 0, math.nan, 0.0, math.nan, 0.0

    def get_state(self):
        """(n, x_prev, x_start, direction, x_ext, amax, n_rev, x_r1, t_r1, x_r2, t_r2): see ``_STATE``."""
        return tuple(getattr(self, k) for k in self._STATE)

    def set_state(self, state):
        if len(state) != len(self._STATE):
            raise ValueError(f'a CycleTracker state has {len(self._STATE)} values {self._STATE}, got {len(state)}')
        for k, v in zip(self._STATE, state, strict=True):
            setattr(self, k, int(v) if k in self._INTS else float(v))

    def _advance(self, x: float) -> bool:
        """One sample through the reversal logic (not the estimates); True if the direction changed."""
        n, s, thr = self.n, self.direction, self.reversal_threshold
        x_prev, self.x_prev, self.n = self.x_prev, x, n + 1
        dev = abs(x - self.x_start)
        if dev > self.amax:
            self.amax = dev
        if s == 0:
            if dev > thr:
                self.direction = 1 if x > self.x_start else -1
                self.x_ext = x
                return True
            return False
        m, sx = s * self.x_ext, s * x
        if sx >= m:                  # at or beyond the extreme: the stretch goes on
            self.x_ext = x
            return False
        if m - sx > thr:             # more than d back: reversal accepted at the extreme
            sp = s * x_prev          # >= m - d (else the previous sample had been accepted)
            self.x_r2, self.t_r2 = self.x_r1, self.t_r1
            self.x_r1, self.t_r1 = self.x_ext, (n - 1) + (sp - (m - thr)) / (sp - sx)
            self.n_rev += 1
            self.direction = -s
            self.x_ext = x
            return True
        return False

    def _estimate(self):
        if self.n_rev >= 2:
            a = max(abs(self.x_r1 - self.x_r2) / 2, AMPLITUDE_FLOOR)
            return a, (self.x_r1 + self.x_r2) / 2, 1.0 / (2.0 * ((self.t_r1 - self.t_r2) * self.dt))
        a = self.default_amplitude if self.default_amplitude is not None else max(self.amax, AMPLITUDE_FLOOR)
        x0 = self.default_center if self.default_center is not None else self.x_start
        f = self.default_frequency if self.default_frequency is not None else math.nan
        return a, x0, f

    def update(self, x: float):
        """Streaming: one displacement sample x [m] -> (A [m], x0 [m], f [Hz]) after it (f NaN if unknown)."""
        self._advance(float(x))
        return self._estimate()

    def run(self, x):
        """Batch: displacements x [m], shape (n,) -> (A, x0, f), arrays of shape (n,), as ``update`` per sample.

        Continues from and updates the same state as ``update``.
        """
        a, x0, f, _ = self._run(x)
        return a, x0, f

    def _run(self, x):
        """``run`` plus the accepted direction after each sample (+1, -1, 0 = none yet), for the elements.

        Only the direction changes are found sequentially: between them the running extreme is a running max (min)
        over a window sized from the previous stretch (doubled until the next change shows up), as in Berg's batch
        path; short stretches (noise larger than d) go sample by sample through ``_advance``.
        """
        x = np.asarray(x, dtype=float).reshape(-1)
        n = x.size
        if n == 0:
            e = np.zeros(0)
            return e, e.copy(), e.copy(), np.zeros(0, dtype=int)
        base, d0, n_rev0 = self.n, self.direction, self.n_rev
        hist_x, hist_t = [self.x_r2, self.x_r1], [self.t_r2, self.t_r1]
        dir_pos, dir_val, rev_pos = [], [], []
        amax = np.maximum.accumulate(np.maximum(np.abs(x - self.x_start), self.amax))
        i, start, width, thr = 0, 0, 64, self.reversal_threshold

        def changed(k):   # the direction changed at batch sample k; the state says how
            dir_pos.append(k)
            dir_val.append(self.direction)
            if self.n_rev != n_rev0 + len(rev_pos):
                rev_pos.append(k)
                hist_x.append(self.x_r1)
                hist_t.append(self.t_r1)

        def advance_at(k):   # the streaming code on batch sample k, from the state just before it
            self.n = base + k
            if k:
                self.x_prev = float(x[k - 1])
            return self._advance(float(x[k]))

        while i < n:
            s = self.direction
            if s == 0:      # virgin: the first sample more than d from the start fixes the direction
                out = np.flatnonzero(np.abs(x[i:] - self.x_start) > thr)
                if out.size == 0:
                    break
                k = i + int(out[0])
                advance_at(k)
                changed(k)
                i, start = k + 1, k
                continue
            if width <= _DENSE:
                # sample by sample until the next direction change, or _DENSE samples without one
                found = False
                for k in range(i, min(i + _DENSE, n)):
                    if advance_at(k):
                        changed(k)
                        width, start, found = 2 * (k - start), k, True
                        break
                i = k + 1
                if not found:
                    width = 4 * _DENSE
                continue
            w = x[i:i + width]
            sw = s * w                                          # exact sign flip: work as if rising
            m = np.maximum.accumulate(np.maximum(sw, s * self.x_ext))   # extreme so far (s-space)
            back = m - sw > thr
            k = int(back.argmax()) if back.any() else w.size    # first sample more than d back
            if k:
                self.x_ext = float(s * m[k - 1])                # exact: s * (s * x) = x
            if k == w.size:
                i += k
                width *= 2
                continue
            advance_at(i + k)                                   # accepts the reversal, the streaming code
            changed(i + k)
            width, start = 2 * (i + k - start), i + k
            i += k + 1
        self.n, self.x_prev, self.amax = base + n, float(x[-1]), float(amax[-1])
        a, x0, f = self._estimates(n, n_rev0, rev_pos, hist_x, hist_t, amax)
        counts = np.diff(np.asarray([0] + dir_pos + [n], dtype=int))
        direction = np.repeat(np.asarray([d0] + dir_val, dtype=int), counts)
        return a, x0, f, direction

    def _estimates(self, n, n_rev0, rev_pos, hist_x, hist_t, amax):
        """(A, x0, f) per sample of a batch of n from the reversal history: sample j has seen the reversals of
        this batch at positions rev_pos up to j (the defaults until two reversals are known).
        """
        c = np.searchsorted(np.asarray(rev_pos, dtype=int), np.arange(n), side='right')
        hx, ht = np.asarray(hist_x, dtype=float), np.asarray(hist_t, dtype=float)
        x1, x2, t1, t2 = hx[c + 1], hx[c], ht[c + 1], ht[c]
        valid = n_rev0 + c >= 2
        span = np.where(valid, t1 - t2, 1.0)
        a = np.where(valid, np.maximum(np.abs(x1 - x2) / 2, AMPLITUDE_FLOOR),
                     self.default_amplitude if self.default_amplitude is not None
                     else np.maximum(amax, AMPLITUDE_FLOOR))
        x0 = np.where(valid, (x1 + x2) / 2,
                      self.default_center if self.default_center is not None else self.x_start)
        f = np.where(valid, 1.0 / (2.0 * (span * self.dt)),
                     self.default_frequency if self.default_frequency is not None else math.nan)
        return a, x0, f
