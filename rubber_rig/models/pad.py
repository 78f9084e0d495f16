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

"""Rail-fastening pad under preload (seed 004): operating-point dependent elastic and elliptic damping forces.

Seed 004 splits the restoring force of a preloaded rubber pad into (Eq. 1, 6)

* an elastic force, an odd polynomial of the *absolute* displacement x [m] measured from the unloaded
  position (Eq. 5): F_k = K1(f, A) x + K3(f, A) x^3 + K5(f, A) x^5 + ... (a preload shows as the mean of x),
* a damping force on an ellipse centred on the mean x0 [m] of the cycle (Eq. 2-4):
  F_c = +-b(f, A) sqrt(1 - ((x - x0)/A)^2), + while x increases, - while it decreases,

whose coefficients depend on the operating point: frequency f [Hz] and amplitude A [m] (Eq. 7-12: K1 quadratic in
A with coefficients cubic in f). A coefficient here is a *trend* (:mod:`.trend`): a number, or a table
c[i][j] with value = sum_ij c[i][j] f^i A^j in SI.

The paper fits each operating point separately and never says how (f, A, x0) are known while the pad moves. In the
time domain a :class:`.cycle_tracker.CycleTracker` estimates them from the last two velocity reversals.

Elements (interface of :mod:`.elements`): :class:`EllipticDamping` (branch 'viscous') and
:class:`OperatingPointSpring` (branch 'elastic'). The analytic first harmonics the catalogue uses are module-level:
:func:`elliptic_first_harmonic`, :func:`odd_polynomial_first_harmonic`, :func:`polynomial_first_harmonic`.
:mod:`.seed004` gives the paper's identified pad in SI (K1, K3 interpolating seed 004 Table 2) and compares it
with Table 2 at Table 1's preloads.

Streaming (``step``/``update``) and batch (``run``) use the same arithmetic (multiplications and additions in the
same order, Horner's scheme, IEEE sqrt), so they agree exactly, not only to round-off.
"""

from __future__ import annotations

import math

import numpy as np

from .cycle_tracker import CycleTracker
from .trend import check_trend, compile_trend, depends_on_frequency, evaluate_trend, trend_value


def elliptic_first_harmonic(b, frequency, amplitude):
    """First-harmonic complex stiffness [N/m] 1j b(f, A) / A of seed 004's elliptic damping force (Eq. 4).

    For x = x0 + A sin(w t) the force on the ellipse centred on x0 with half-axes A and b is b cos(w t):
    purely in phase with velocity, loop area pi b A (Eq. 3).

    Parameters
    ----------
    b : float or 2-D nested sequence
        Half-axis b [N], a number or a trend (:func:`trend_value`).
    frequency, amplitude : float or array
        f [Hz] (may be None if b does not depend on it), A [m]; broadcast.

    Returns
    -------
    complex ndarray
        Broadcast shape of ``frequency`` and ``amplitude``.
    """
    a = np.asarray(amplitude, dtype=float)
    bv = trend_value(b, frequency, a)
    return np.asarray(1j * np.asarray(bv, dtype=float) / a, dtype=complex)


def _elliptic_off_size(b, ratio):
    """Cos-coefficient [N] of F = sign(cos t) b sqrt(max(0, 1 - r^2 sin^2 t)), r = a/A: a sine of amplitude a
    through an ellipse of fixed half-axis A. (4 b / pi) int_0^1 sqrt(1 - r^2 u^2) du, closed form.
    """
    r = np.asarray(ratio, dtype=float)
    rc = np.minimum(r, 1.0)
    inside = 2 * b / np.pi * (np.sqrt(1 - rc ** 2) + np.where(rc > 0, np.arcsin(rc) / np.where(rc > 0, rc, 1), 1))
    return np.where(r <= 1.0, inside, b / np.where(r > 0, r, 1))


class _TrackedElement:
    """An element whose whole state is its operating point: a :class:`CycleTracker` at ``self.tracker``."""

    def reset(self, x0: float = 0.0):
        self.tracker.reset(x0)

    def get_state(self):
        return self.tracker.get_state()

    def set_state(self, state):
        self.tracker.set_state(state)


class EllipticDamping(_TrackedElement):
    """Seed 004's elliptic damping force (Eq. 4), branch 'viscous'.

        F_c = s b(f, A) sqrt(max(0, 1 - ((x - x0) / A)^2))   [N],

    s = +1 while x increases, -1 while it decreases (the :class:`CycleTracker`'s accepted direction, 0 before the
    first motion), so for x = x0 + A sin(w t) the force is b cos(w t) = (b / (A w)) v: it dissipates like a
    dashpot, pi b A per cycle (Eq. 3). The clamp at 0 covers x outside the estimated ellipse (growing amplitude).

    With ``amplitude`` and ``center`` both given the operating point is fixed: A, x0 and f = ``frequency`` are the
    given values (the paper's form at one excitation case); the tracker only supplies the direction. Otherwise
    (A, x0, f) are the tracker's estimates, with the given values as its defaults before two reversals. With a
    deadband d > 0 the sign flips d after the extreme, where the force is still about b sqrt(2 d / A).

    Parameters
    ----------
    b : float or 2-D nested sequence
        Half-axis b [N] = E / (pi A) (Eq. 3), a number or a trend c[i][j] in N / (Hz^i m^j).
    dt : float
        Sample period [s].
    amplitude, center, frequency : float or None
        A [m], x0 [m], f [Hz]; ``frequency`` is required if b depends on f.
    reversal_threshold : float
        Reversal deadband d [m] of the tracker.
    """

    kinds = ('viscous',)
    branch_names = ('viscous',)

    def __init__(self, b, dt: float, amplitude=None, center=None, frequency=None, reversal_threshold: float = 0.0):
        self.b = check_trend('b', b)
        self._b = compile_trend(self.b)
        self.tracker = CycleTracker(dt, amplitude, center, frequency, reversal_threshold)
        self.dt = self.tracker.dt
        if depends_on_frequency(self._b) and self.tracker.default_frequency is None:
            raise ValueError('parameter frequency (default f [Hz]) is required: b depends on frequency, which is '
                             'unknown until two reversals have been seen')
        self.fixed = amplitude is not None and center is not None
        tr = self.tracker
        self.amplitude, self.center, self.frequency = tr.default_amplitude, tr.default_center, tr.default_frequency

    def step(self, x: float):
        x = float(x)
        a, x0, f = self.tracker.update(x)
        if self.fixed:
            a, x0, f = self.amplitude, self.center, self.frequency
        s = self.tracker.direction
        u = (x - x0) / a
        b = evaluate_trend(self._b, math.nan if f is None else f, a)
        return (s * b * math.sqrt(max(0.0, 1.0 - u * u)),)

    def run(self, x):
        x = np.asarray(x, dtype=float).reshape(-1)
        a, x0, f, s = self.tracker._run(x)
        if self.fixed:
            a, x0, f = self.amplitude, self.center, math.nan if self.frequency is None else self.frequency
        u = (x - x0) / a
        b = evaluate_trend(self._b, f, a)
        return (s * b * np.sqrt(np.maximum(0.0, 1.0 - u * u)))[None, :]

    def complex_stiffness(self, frequency, amplitude):
        """Exact first-harmonic complex stiffness [N/m], shape (1, ...), for x = x0 + a sin(w t).

        Tracked operating point: 1j b(f, a) / a (:func:`elliptic_first_harmonic`). Fixed operating point (A, x0,
        f given) and a sine about that centre: 1j (2 b / (pi a)) (sqrt(1 - r^2) + arcsin(r) / r), r = a / A <= 1,
        and 1j b A / a^2 for r > 1 (clamped ellipse); = 1j b / A at a = A.
        """
        if not self.fixed:
            return elliptic_first_harmonic(self.b, frequency, amplitude)[None]
        a = np.asarray(amplitude, dtype=float) + 0 * np.asarray(frequency, dtype=float)
        b = evaluate_trend(self._b, math.nan if self.frequency is None else self.frequency, self.amplitude)
        return np.asarray(1j * _elliptic_off_size(b, a / self.amplitude) / a, dtype=complex)[None]


# ---------------------------------------------------------------------------------------------------- elastic

def polynomial_first_harmonic(coefficients, amplitude, mean=0.0):
    """First-harmonic stiffness [N/m] F1 / A of P(x) = a0 + a1 x + a2 x^2 + ... for x = m + A sin(t).

    Exact: (m + A sin t)^n = sum_k C(n, k) m^(n-k) A^k sin^k t, and the first Fourier sine coefficient of sin^k t
    is C(k, (k-1)/2) / 4^((k-1)/2) for odd k (0 for even k), so

        F1 / A = sum_n a_n sum_{j: 2j+1 <= n} C(n, 2j+1) C(2j+1, j) 4^-j m^(n-2j-1) A^(2j).

    At A = 0 this is P'(m), the tangent stiffness. The force is elastic, so the result is real (complex dtype, as
    the catalogue's complex stiffnesses).

    Parameters
    ----------
    coefficients : sequence of float or array
        a_n [N/m^n], n = 0, 1, ...; entries may be arrays (e.g. trends evaluated over a grid), broadcast.
    amplitude : float or array
        A [m].
    mean : float or array
        m [m], the mean displacement (a preload); broadcast with ``amplitude``.

    Returns
    -------
    complex ndarray
        Broadcast shape of the coefficients, ``amplitude`` and ``mean``.
    """
    a = np.asarray(amplitude, dtype=float)
    m = np.asarray(mean, dtype=float)
    coefficients = list(coefficients)
    if not coefficients:
        raise ValueError('parameter coefficients of the polynomial must not be empty')
    total = np.zeros(np.broadcast_shapes(a.shape, m.shape, *(np.shape(c) for c in coefficients)))
    a2 = a * a
    for n, c in enumerate(coefficients):
        for j in range((n - 1) // 2 + 1 if n >= 1 else 0):
            weight = math.comb(n, 2 * j + 1) * math.comb(2 * j + 1, j) / 4.0 ** j
            total = total + np.asarray(c, dtype=float) * weight * m ** (n - 2 * j - 1) * a2 ** j
    return np.asarray(total, dtype=complex)


def odd_polynomial_first_harmonic(k_odd, amplitude, mean=0.0):
    """First-harmonic stiffness [N/m] of seed 004's elastic force (Eq. 5) K1 x + K3 x^3 + ... for x = m + A sin(t).

    About the unloaded position (m = 0): K1 + 3/4 K3 A^2 + 10/16 K5 A^4 + ..., term K_(2j+1) C(2j+1, j) 4^-j A^(2j).
    With a preload m != 0 the even powers of (m + A sin t) add to it (:func:`polynomial_first_harmonic`).

    Parameters
    ----------
    k_odd : sequence of float or array
        (K1 [N/m], K3 [N/m^3], K5 [N/m^5], ...) at the operating point; arrays broadcast.
    amplitude, mean : float or array
        A [m], m [m].

    Returns
    -------
    complex ndarray
        Broadcast shape of the inputs.
    """
    k_odd = list(k_odd)
    if not k_odd:
        raise ValueError('parameter k_odd must not be empty')
    coefficients = [0.0] * (2 * len(k_odd))
    coefficients[1::2] = k_odd
    return polynomial_first_harmonic(coefficients, amplitude, mean)


class OperatingPointSpring(_TrackedElement):
    """Seed 004's elastic force (Eq. 5, 7), branch 'elastic'.

        F_k = sum_i K_(2i-1)(f, A) x^(2i-1)   [N],

    x [m] absolute, measured from the unloaded position as in the paper (a preload is the mean of x, negative in
    compression, and F_k has the sign of x). Each K is a number or a trend (:func:`trend_value`); (f, A) are the
    :class:`CycleTracker`'s estimates, with ``frequency`` and ``amplitude`` as its defaults before two reversals.
    The coefficients change at reversals only, so the force is elastic within each half cycle.

    Parameters
    ----------
    k_odd : sequence
        (K1 [N/m], K3 [N/m^3], K5 [N/m^5], ...), each a number or a table c[i][j] in SI per Hz^i m^j.
    dt : float
        Sample period [s].
    frequency, amplitude : float or None
        Default f [Hz] (required if a K depends on f) and A [m].
    reversal_threshold : float
        Reversal deadband d [m] of the tracker.
    """

    kinds = ('elastic',)
    branch_names = ('elastic',)

    def __init__(self, k_odd, dt: float, frequency=None, amplitude=None, reversal_threshold: float = 0.0):
        if isinstance(k_odd, (str, bytes)) or not hasattr(k_odd, '__iter__'):
            raise ValueError(f'parameter k_odd must be a sequence (K1, K3, ...), got {k_odd!r}')
        self.k_odd = tuple(check_trend(f'k_odd[{i}] (K{2 * i + 1})', k) for i, k in enumerate(k_odd))
        if not self.k_odd:
            raise ValueError('parameter k_odd must not be empty')
        self._k = tuple(compile_trend(k) for k in self.k_odd)
        self.tracker = CycleTracker(dt, amplitude, None, frequency, reversal_threshold)
        self.dt = self.tracker.dt
        self.frequency, self.amplitude = self.tracker.default_frequency, self.tracker.default_amplitude
        needs_f = [f'K{2 * i + 1}' for i, k in enumerate(self._k) if depends_on_frequency(k)]
        if needs_f and self.frequency is None:
            raise ValueError(f'parameter frequency (default f [Hz]) is required: {", ".join(needs_f)} depend(s) on '
                             f'frequency, which is unknown until two reversals have been seen')

    def coefficients(self, frequency, amplitude):
        """(K1, K3, ...) in SI at f [Hz] and A [m] (floats or broadcast arrays)."""
        return tuple(trend_value(k, frequency, amplitude) for k in self.k_odd)

    def _force(self, x, f, a):
        # Horner in x^2: x (K1 + x^2 (K3 + x^2 K5 ...)), the same operations for floats and arrays
        x2 = x * x
        acc = evaluate_trend(self._k[-1], f, a)
        for k in reversed(self._k[:-1]):
            acc = acc * x2 + evaluate_trend(k, f, a)
        return x * acc

    def step(self, x: float):
        x = float(x)
        a, _, f = self.tracker.update(x)
        return (self._force(x, f, a),)

    def run(self, x):
        x = np.asarray(x, dtype=float).reshape(-1)
        a, _, f, _ = self.tracker._run(x)
        return (self._force(x, f, a) + np.zeros(x.shape))[None, :]

    def complex_stiffness(self, frequency, amplitude, mean=0.0):
        """Exact first-harmonic stiffness [N/m], shape (1, ...), for x = mean + A sin(w t) with the coefficients
        at (f, A): K1 + 3/4 K3 A^2 + 10/16 K5 A^4 + ... about the unloaded position (mean = 0, the default),
        :func:`odd_polynomial_first_harmonic` otherwise. Real: the force is elastic.
        """
        f = None if frequency is None else np.asarray(frequency, dtype=float)
        a = np.asarray(amplitude, dtype=float)
        if f is not None:
            f, a = np.broadcast_arrays(f, a)
        return odd_polynomial_first_harmonic(self.coefficients(f, a), a, mean)[None]
