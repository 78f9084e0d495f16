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

"""Friction elements: Berg's smooth friction (seed 000 Eq. 16-22) and smooth Coulomb (seed 002).

Berg's element remembers a reference state (x_s, F_fs); following seed 000 Section 5.2 it is
updated to the previous sample's displacement and friction force whenever the sign of the
displacement increment changes (a zero increment keeps the last direction). Between reversals the
force is the closed form of Eq. 16, which is what makes the batch path vectorised: only the
reference states at the reversals are computed sequentially.

Reversal deadband (``reversal_threshold`` d [m], default 0 = exactly the paper's rule). Driven by a
*measured* displacement, the paper's rule takes every sensor-noise wiggle for a velocity reversal
and resets the reference state, so the friction loop collapses: the friction energy per cycle (Eq. 18)
comes out low, and the more so the higher the sample rate, because more samples mean more noise
reversals per cycle. With d > 0 a reversal is only accepted once the displacement has moved more than d back from
the extreme x_ext reached since the last accepted reversal, and the new reference state is the
state at that extreme (x_ext, F(x_ext)), not the noisy previous sample. Before acceptance, a sample
back inside the band already follows Eq. 16 from the candidate reference (x_ext, F(x_ext)) -- the
branch it joins if the reversal is accepted -- so the force stays continuous at acceptance, and a
wiggle that returns past x_ext rejoins the current branch exactly at (x_ext, F(x_ext)): a wiggle
inside the band dissipates nothing and leaves no trace in the state. In the virgin state the element
follows the virgin curve from (x_0, 0) both ways until the displacement first leaves
(x_0 - d, x_0 + d), which fixes the first direction.

Choosing d: about 10x the displacement noise RMS, well below the smallest amplitude of interest.
What d must exceed is the spread between the running extreme of the noisy samples and a later
sample, which grows with the number of samples spent near the extreme - most in slow motion, such
as seed 001's quasi-static 0.05 mm/s triangle (50 nm per sample): there 5x the RMS still lets noise
dips through, 10x does not (test_models_friction checks 10x on that triangle at 1 and 5 kHz).
The price: a real reversal smaller than d is not a reversal any more. On a clean signal
without such small reversals the reference states are exactly the paper's, so the forces agree
with d = 0 to round-off; but where the paper's rule restarts a fresh (stiff, F_fmax/x2) branch after
a tiny real reversal -- e.g. a few-nm servo overshoot where the motion stops and resumes in the
same direction -- the deadband keeps the current branch, and the two can differ by tens of newtons
for several cycles. With d = 0 every sign change of the increment is a reversal: exactly the paper's rule.
"""
from __future__ import annotations

import math

import numpy as np

from .deadband import cached_schedule
from .elements import VelocityElement


def berg_force(x, x_s, f_s, f_fmax: float, x2: float):
    """Berg friction force [N] (seed 000 Eq. 16) for displacement ``x`` [m] and reference (x_s [m], f_s [N]).

    Broadcasts over arrays; identical arithmetic for scalars and arrays so streaming and batch agree.
    """
    d = np.subtract(x, x_s)
    mu = np.divide(f_s, f_fmax)
    up = d > 0
    # Eq. 16 both branches at once: F = F_fs + d A / (B + |d|), no division by zero at d = 0
    a = np.where(up, f_fmax - f_s, f_fmax + f_s)
    b = np.where(up, x2 * (1.0 - mu), x2 * (1.0 + mu))
    return f_s + d * a / (b + np.abs(d))


def _berg_scalar(x, x_s, f_s, f_fmax, x2):
    d = x - x_s
    mu = f_s / f_fmax
    if d > 0:
        return f_s + d * (f_fmax - f_s) / (x2 * (1.0 - mu) + d)
    return f_s + d * (f_fmax + f_s) / (x2 * (1.0 + mu) - d)


def _berg_peak_force(f_fmax, x2, x0):
    # Eq. 17 on the arguments as given (Python floats and numpy arrays round x2 ** 2 differently)
    return f_fmax / (2.0 * x2) * (np.sqrt(x2 ** 2 + x0 ** 2 + 6.0 * x2 * x0) - x2 - x0)


def _berg_energy(f_fmax, x2, x0, mu0):
    # Eq. 18 with mu0 = F_f0 / F_fmax, on the arguments as given
    a = x2 * (1.0 + mu0)
    return 2.0 * f_fmax * (2.0 * x0 - a * (1.0 + mu0) * np.log((a + 2.0 * x0) / a))


def berg_peak_force(f_fmax, x2, x0):
    """Seed 000 Eq. 17: steady-state friction force amplitude F_f0 [N] for amplitude ``x0`` [m]. Broadcasts."""
    return _berg_peak_force(np.asarray(f_fmax, float), np.asarray(x2, float), np.asarray(x0, float))


def berg_energy(f_fmax, x2, x0):
    """Seed 000 Eq. 18: energy [J] dissipated per steady cycle by Berg's element (loop area). Broadcasts."""
    mu0 = berg_peak_force(1.0, x2, x0)
    return _berg_energy(np.asarray(f_fmax, float), np.asarray(x2, float), np.asarray(x0, float), mu0)


def berg_steady_state(amplitude, f_fmax: float, x2: float):
    """Steady-state Berg properties for x = x0 sin(wt) (seed 000 Eq. 17-22).

    Returns dict of arrays: f_f0 [N] force amplitude (Eq. 17), energy [J] per cycle (Eq. 18),
    k_df [N/m] (Eq. 19), d_f [-] (Eq. 20), k_fs, k_fl [N/m] (Eq. 21, 22).
    """
    x0 = np.asarray(amplitude, dtype=float)
    f0 = _berg_peak_force(f_fmax, x2, x0)
    energy = _berg_energy(f_fmax, x2, x0, f0 / f_fmax)
    k_df = f0 / x0
    d_f = energy / (np.pi * f0 * x0)
    return {'f_f0': f0, 'energy': energy, 'k_df': k_df, 'd_f': d_f,
            'k_fs': k_df * np.sqrt(1 - d_f ** 2), 'k_fl': k_df * d_f}


# Gauss-Legendre nodes on [-pi/2, pi/2] for the ascending branch x = x0 sin(theta).
# The integrand is smooth (analytic in theta for x0 > 0), so 48 nodes give ~1e-12 relative error.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(48)
_THETA = 0.5 * np.pi * _GL_X
_WEIGHT = 0.5 * np.pi * _GL_W
_SIN = np.sin(_THETA)
_COS = np.cos(_THETA)


def friction_first_harmonic(f_fmax, x2, x0):
    """Complex first-harmonic stiffness of the steady Berg loop under x = x0 sin(wt).

    Returns K_f = (b1 + j a1) / x0 where F_f(t) ~ b1 sin(wt) + a1 cos(wt). Rate independent.
    """
    f_fmax, x2, x0 = np.broadcast_arrays(*(np.asarray(v, float) for v in (f_fmax, x2, x0)))
    mu0 = berg_peak_force(1.0, x2, x0)[..., None]          # F_f0 / F_fmax
    x2e, x0e = x2[..., None], x0[..., None]
    d = x0e * (_SIN + 1.0)                                  # x - x_s on the ascending branch
    g = -mu0 + d / (x2e * (1.0 + mu0) + d) * (1.0 + mu0)    # F_f / F_fmax, Eq. 16 with mu = -mu0
    # Full cycle = ascending branch + its odd mirror: sin-coefficient doubles, cos-coefficient doubles.
    b1 = (2.0 / np.pi) * np.sum(_WEIGHT * g * _SIN, axis=-1)
    a1 = (2.0 / np.pi) * np.sum(_WEIGHT * g * _COS, axis=-1)
    return f_fmax * (b1 + 1j * a1) / x0


def check_reversal_threshold(d: float, given, name: str = 'reversal_threshold') -> float:
    """``d``, the reversal deadband [m] converted from the ``given`` value of parameter ``name``, if it
    is finite and >= 0; else ValueError naming the parameter and the given value.
    """
    if not (math.isfinite(d) and d >= 0.0):
        raise ValueError(f'parameter {name} must be a finite displacement >= 0 [m], got {given!r}')
    return d


class BergFriction:
    """Berg's smooth friction element (2 parameters: f_fmax [N], x2 [m]); branch 'friction'.

    ``reversal_threshold`` [m] (>= 0): the reversal deadband d of the module docstring; 0 is the
    paper's rule. It is a setting of the element, not part of its state.
    """

    branch_names = ('friction',)
    kinds = ('friction',)
    SHORT_RUN = 32      # [samples] up to this many, run() steps sample by sample (the same numbers, faster)

    def __init__(self, f_fmax: float, x2: float, dt: float, reversal_threshold: float = 0.0):
        self.f_fmax, self.x2, self.dt = float(f_fmax), float(x2), float(dt)
        self.reversal_threshold = check_reversal_threshold(float(reversal_threshold), reversal_threshold)
        self.reset()

    def reset(self, x0: float = 0.0):
        """Virgin state at x0 [m]: reference (x0, 0), no direction yet."""
        self.x_prev, self.direction, self.x_s, self.f_s, self.f_prev = float(x0), 0, float(x0), 0.0, 0.0
        self.x_ext, self.f_ext = float(x0), 0.0

    def get_state(self):
        """(x_prev, direction, x_s, f_s, f_prev, x_ext, f_ext): last sample, accepted direction (0 =
        virgin), reference state, and the extreme reached in that direction with its force (with
        d = 0 the extreme is always the last sample).
        """
        return (self.x_prev, self.direction, self.x_s, self.f_s, self.f_prev, self.x_ext, self.f_ext)

    def set_state(self, state):
        if len(state) != 7:
            raise ValueError(f'a Berg state has 7 values (x_prev, direction, x_s, f_s, f_prev, x_ext, f_ext), '
                             f'got {len(state)}')
        (self.x_prev, self.direction, self.x_s, self.f_s, self.f_prev, self.x_ext, self.f_ext) = state
        self.direction = int(self.direction)

    def step(self, x: float):
        return (self._step_deadband(x) if self.reversal_threshold > 0.0 else self._step_plain(x),)

    def _step_plain(self, x: float) -> float:
        d = x - self.x_prev
        direction = 1 if d > 0 else (-1 if d < 0 else self.direction)
        if direction != self.direction and self.direction != 0:
            self.x_s, self.f_s = self.x_prev, self.f_prev   # reversal: previous sample becomes reference
        self.direction = direction
        f = _berg_scalar(x, self.x_s, self.f_s, self.f_fmax, self.x2)
        self.x_prev, self.f_prev = x, f
        self.x_ext, self.f_ext = x, f
        return f

    def _step_deadband(self, x: float) -> float:
        fm, x2, thr, s = self.f_fmax, self.x2, self.reversal_threshold, self.direction
        if s == 0:                              # virgin: Eq. 16 from (x0, 0) both ways until |x - x0| > d
            f = _berg_scalar(x, self.x_s, self.f_s, fm, x2)
            if abs(x - self.x_s) > thr:
                self.direction = 1 if x > self.x_s else -1
                self.x_ext, self.f_ext = x, f
        elif s * x >= s * self.x_ext:            # at or beyond the extreme: the current branch goes on
            f = _berg_scalar(x, self.x_s, self.f_s, fm, x2)
            self.x_ext, self.f_ext = x, f
        elif s * self.x_ext - s * x <= thr:      # back inside the band: the candidate branch from the extreme
            f = _berg_scalar(x, self.x_ext, self.f_ext, fm, x2)
        else:                                   # more than d back: reversal accepted at the extreme
            self.x_s, self.f_s, self.direction = self.x_ext, self.f_ext, -s
            f = _berg_scalar(x, self.x_s, self.f_s, fm, x2)
            self.x_ext, self.f_ext = x, f
        self.x_prev, self.f_prev = x, f
        return f

    def run(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        n = x.size
        if n == 0:
            return np.zeros((1, 0))
        if n <= self.SHORT_RUN:
            # a few samples (a batch of the online model): step() per sample is the same arithmetic (Eq. 16 as
            # _berg_scalar) to the bit, without the batch form's dozen numpy calls
            step = self._step_deadband if self.reversal_threshold > 0.0 else self._step_plain
            return np.array([[step(v) for v in x.tolist()]])
        if self.reversal_threshold > 0.0:
            return self._run_deadband(x)[None, :]
        xp = np.empty(n + 1)
        xp[0] = self.x_prev
        xp[1:] = x
        direction = np.sign(np.diff(xp))
        if not direction.all():
            # zero increments keep the last non-zero direction (initially the stored one)
            idx = np.where(direction != 0, np.arange(n), -1)
            np.maximum.accumulate(idx, out=idx)
            direction = np.where(idx >= 0, direction[np.maximum(idx, 0)], float(self.direction))
        rev = np.flatnonzero(direction[1:] != direction[:-1]) + 1
        if self.direction != 0 and direction[0] != self.direction:
            rev = np.concatenate(([0], rev))
        # reference state per segment: sequential only over the reversals
        fm, x2 = self.f_fmax, self.x2
        x_s, f_s, f_prev = self.x_s, self.f_s, self.f_prev
        x_s_seg, f_s_seg = [x_s], [f_s]
        xl = xp[rev].tolist()
        for k, i in enumerate(rev.tolist()):
            if i > 0:
                f_prev = _berg_scalar(xl[k], x_s, f_s, fm, x2)
            x_s, f_s = xl[k], f_prev
            x_s_seg.append(x_s)
            f_s_seg.append(f_s)
        bounds = np.concatenate(([0], rev, [n]))
        counts = np.diff(bounds)
        x_s_a, f_s_a = np.array(x_s_seg), np.array(f_s_seg)
        if counts[0] == 0:   # reversal at the first sample: the stored reference has no samples
            x_s_a, f_s_a, counts, bounds = x_s_a[1:], f_s_a[1:], counts[1:], bounds[1:]
        seg_dir = direction[bounds[:-1]]
        # Eq. 16 in one expression: F = F_fs + d A / (B + |d|), A and B per segment and direction
        mu = f_s_a / fm
        a_coef = np.where(seg_dir > 0, fm - f_s_a, fm + f_s_a)
        b_coef = np.where(seg_dir > 0, x2 * (1.0 - mu), x2 * (1.0 + mu))
        d = x - np.repeat(x_s_a, counts)
        f = np.repeat(f_s_a, counts) + d * np.repeat(a_coef, counts) / (np.repeat(b_coef, counts) + np.abs(d))
        self.x_prev, self.direction = float(x[-1]), int(direction[-1])
        self.x_s, self.f_s, self.f_prev = x_s, f_s, float(f[-1])
        self.x_ext, self.f_ext = self.x_prev, self.f_prev
        return f[None, :]

    def _run_deadband(self, x: np.ndarray) -> np.ndarray:
        """Batch form of ``_step_deadband``, the same arithmetic per sample, in two parts.

        Which reversals are accepted, and which reference each sample follows, depends on the displacement
        and d alone, never on f_fmax or x2 (``deadband.deadband_schedule``); a fit runs the element hundreds of
        times over the same measured displacement with other parameters, so the schedule is kept
        (``deadband.cached_schedule``) and each run is then one scalar step per accepted reversal (the reference
        forces, Eq. 16 at each accepted extreme) and one vectorised Eq. 16 over all samples.
        """
        fm, x2, was = self.f_fmax, self.x2, self.direction
        sched = cached_schedule(x, self.reversal_threshold, was, self.x_ext, self.x_s)
        xe0, fe0 = self.x_ext, self.f_ext
        refs = sched.refs
        xs = np.empty(len(refs) + 1)
        fs = np.empty(len(refs) + 1)
        xs[0], fs[0] = self.x_s, self.f_s
        for k, xk in enumerate(refs, start=1):
            # the reference force is F at the accepted extreme on the previous branch; an extreme carried in
            # from the last call keeps its stored force
            carried = k == 1 and was != 0 and xk == xe0
            fs[k] = fe0 if carried else _berg_scalar(xk, xs[k - 1], fs[k - 1], fm, x2)
            xs[k] = xk
        seg, cand = sched.segment, sched.candidate
        ref_x, ref_f = xs[seg], fs[seg]
        if cand.size:
            ext, cseg = sched.extreme, seg[cand]
            f_ext = berg_force(ext, xs[cseg], fs[cseg], fm, x2)
            if was != 0:
                f_ext = np.where((cseg == 0) & (ext == xe0), fe0, f_ext)   # a carried extreme keeps its force
            ref_x[cand], ref_f[cand] = ext, f_ext
        f = berg_force(x, ref_x, ref_f, fm, x2)
        self.direction = sched.direction
        self.x_s, self.f_s = float(xs[-1]), float(fs[-1])
        if sched.direction != 0:
            last_seg = len(refs)
            if was != 0 and sched.x_ext == xe0 and last_seg == 0:
                self.f_ext = fe0
            else:
                self.f_ext = _berg_scalar(sched.x_ext, self.x_s, self.f_s, fm, x2)
            self.x_ext = sched.x_ext
        self.x_prev, self.f_prev = float(x[-1]), float(f[-1])
        return f

    def complex_stiffness(self, frequency, amplitude):
        """Equivalent complex stiffness K_fs + j K_fl [N/m] (seed 000 Eq. 21-22), shape (1, ...)."""
        ss = berg_steady_state(amplitude, self.f_fmax, self.x2)
        return np.asarray(ss['k_fs'] + 1j * ss['k_fl'] + 0 * np.asarray(frequency, dtype=float))[None]


class SmoothCoulomb(VelocityElement):
    """Smooth Coulomb friction F = F_c tanh(a v) (seed 002 Eq. 46); v from the backward difference.

    f_c [N] friction force level, a [s/m] steepness. Branch 'friction'.
    """

    branch_names = ('friction',)
    kinds = ('friction',)

    def __init__(self, f_c: float, a: float, dt: float):
        self.f_c, self.a = float(f_c), float(a)
        super().__init__(dt)

    def force_of_velocity(self, v):
        return self.f_c * np.tanh(self.a * v)

    def complex_stiffness(self, frequency, amplitude, n_quad: int = 512):
        """First-harmonic (describing-function) stiffness [N/m] of the continuous element, by quadrature.

        For x = x0 sin(wt), F = F_c tanh(a w x0 cos(wt)) is in phase with velocity: purely loss,
        K_l = (1/(pi x0)) * int_0^{2 pi} F cos(theta) d theta.
        """
        f, x0 = np.broadcast_arrays(np.asarray(frequency, float), np.asarray(amplitude, float))
        th = (np.arange(n_quad) + 0.5) * 2 * np.pi / n_quad
        vel = 2 * np.pi * f[..., None] * x0[..., None] * np.cos(th)
        k_l = (self.f_c * np.tanh(self.a * vel) * np.cos(th)).mean(-1) * 2 / x0
        return np.asarray(1j * k_l)[None]
