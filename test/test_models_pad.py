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

"""Seed 004's preloaded rail-fastening pad: trends, cycle tracker, elliptic damping, operating-point spring."""
import math

import numpy as np
import pytest

from rubber_rig.models.cycle_tracker import AMPLITUDE_FLOOR, CycleTracker
from rubber_rig.models.pad import (
    EllipticDamping,
    OperatingPointSpring,
    elliptic_first_harmonic,
    odd_polynomial_first_harmonic,
    polynomial_first_harmonic,
)
from rubber_rig.models.seed004 import seed004_pad_spec, seed004_table2_check
from rubber_rig.models.trend import check_trend, trend_value

DT = 1e-3           # [s] 1 kHz
F0, A0, X0 = 4.0, 0.5e-3, -1e-3   # [Hz], [m], [m]: a Table 1 like case (mean = preload, compression < 0)
PER = int(round(1 / (F0 * DT)))    # samples per cycle
NOISE = 0.2e-6      # [m] displacement noise of the simulated rig


def sine(frequency=F0, amplitude=A0, mean=X0, cycles=6, dt=DT):
    t = np.arange(int(round(cycles / (frequency * dt)))) * dt
    return mean + amplitude * np.sin(2 * np.pi * frequency * t)


def first_harmonic(signal, per, cycles):
    """Complex amplitude of the fundamental over the last ``cycles`` whole cycles (DFT bin)."""
    s = np.asarray(signal)[-per * cycles:]
    k = np.arange(s.size)
    return 2.0 / s.size * np.sum(s * np.exp(-2j * np.pi * k / per))


def harmonic_stiffness(x, force, per, cycles=4):
    return first_harmonic(force, per, cycles) / first_harmonic(x, per, cycles)


def streamed(element, x, x0=0.0):
    element.reset(x0)
    return np.array([element.step(v) for v in x]).T


def batched(element, x, x0=0.0, chunks=(1, 7, 130, 999)):
    """Batch run in uneven chunks: every chunk continues the state of the last."""
    element.reset(x0)
    out, i, c = [], 0, 0
    while i < x.size:
        k = chunks[c % len(chunks)]
        out.append(element.run(x[i:i + k]))
        i, c = i + k, c + 1
    return np.concatenate(out, axis=1)


# ------------------------------------------------------------------------------------------------------- trends

def test_trend_constant_and_table():
    assert trend_value(5.0, 3.0, 1e-3) == 5.0
    assert trend_value(5.0, None, 1e-3) == 5.0
    np.testing.assert_array_equal(trend_value(2.5, [1.0, 2.0], 1e-3), [2.5, 2.5])
    c = [[1.0, 2e3, 3e6], [4.0, 5e3, 6e6]]
    f = np.array([[2.0], [6.0], [10.0]])
    a = np.array([0.3e-3, 0.5e-3, 0.7e-3, 1e-3])
    expected = (1 + 2e3 * a + 3e6 * a ** 2) + f * (4 + 5e3 * a + 6e6 * a ** 2)
    got = trend_value(c, f, a)
    assert got.shape == (3, 4)
    np.testing.assert_allclose(got, expected, rtol=1e-14)
    assert trend_value(c, 2.0, 0.5e-3) == pytest.approx(1 + 1 + 0.75 + 2 * (4 + 2.5 + 1.5), rel=1e-14)
    # a table without frequency rows never needs f; with them, f is required
    assert trend_value([[1.0, 2e3]], None, 1e-3) == pytest.approx(3.0, rel=1e-14)
    with pytest.raises(ValueError, match='frequency'):
        trend_value(c, None, 1e-3)


def test_check_trend_normalises_and_names_the_parameter():
    assert check_trend('k1', 3) == 3.0
    assert check_trend('k1', np.float32(2.0)) == 2.0
    assert check_trend('k1', np.array([[1, 2], [3, 4]])) == ((1.0, 2.0), (3.0, 4.0))
    for bad in ([[1.0, 2.0], [3.0]], [[1.0, math.nan]], [[1.0], [math.inf]], math.nan, [], [[]], [1.0, 2.0],
                'abc', None, [[1.0, 'x']], True):
        with pytest.raises(ValueError, match='k3'):
            check_trend('k3', bad)
    with pytest.raises(ValueError, match='ragged'):
        check_trend('b', [[1.0, 2.0], [3.0]])
    with pytest.raises(ValueError, match=r'b: entry \[0\]\[1\]'):
        check_trend('b', [[1.0, math.nan]])


def test_frequency_dependent_coefficient_needs_a_default_frequency():
    table = [[1e3, 2e6], [10.0, 0.0]]
    with pytest.raises(ValueError, match='frequency'):
        EllipticDamping(table, DT)
    with pytest.raises(ValueError, match='K3'):
        OperatingPointSpring([1e6, table], DT)
    EllipticDamping(table, DT, frequency=4.0)
    OperatingPointSpring([1e6, table], DT, frequency=4.0)
    # a trailing zero frequency row is no dependence
    EllipticDamping([[1e3, 2e6], [0.0, 0.0]], DT)
    with pytest.raises(ValueError, match='k_odd'):
        OperatingPointSpring([1e6, [[1.0], [2.0, 3.0]]], DT)
    with pytest.raises(ValueError, match='dt'):
        CycleTracker(0.0)
    with pytest.raises(ValueError, match='amplitude'):
        CycleTracker(DT, amplitude=-1e-3)
    with pytest.raises(ValueError, match='reversal_threshold'):
        CycleTracker(DT, reversal_threshold=-1e-6)


# ---------------------------------------------------------------------------------------------- cycle tracker

def test_tracker_on_a_sine():
    x = sine(cycles=4)
    tr = CycleTracker(DT)
    tr.reset(x[0])
    a, x0, f = tr.run(x)
    settled = slice(2 * PER, None)
    # extremes at the samples nearest the true ones; reversal times quantised to dt (+-1 sample in 125)
    np.testing.assert_allclose(a[settled], A0, rtol=1e-3)
    np.testing.assert_allclose(x0[settled], X0, rtol=1e-3)
    np.testing.assert_allclose(f[settled], F0, rtol=0.01)
    assert tr.n_rev == 8                        # extremes at 1/4, 3/4, ... 15/4 cycles


def test_tracker_defaults_before_two_reversals():
    x = sine(cycles=1)
    tr = CycleTracker(DT)
    tr.reset(X0)
    a, x0, f = tr.run(x)
    first_peak = PER // 4
    # before the first reversal: running max |x - x_start|, centre x_start, f unknown
    np.testing.assert_array_equal(a[1:first_peak], np.abs(x[1:first_peak] - X0))
    assert a[0] == AMPLITUDE_FLOOR              # x[0] = x_start: A floored, never 0
    assert np.all(x0[:3 * PER // 4] == X0) and np.all(np.isnan(f[:3 * PER // 4]))
    assert np.all(a > 0)
    tr = CycleTracker(DT, amplitude=0.4e-3, center=-1.2e-3, frequency=3.0)
    tr.reset(X0)
    a, x0, f = tr.run(x[:3 * PER // 4])
    assert np.all(a == 0.4e-3) and np.all(x0 == -1.2e-3) and np.all(f == 3.0)


@pytest.mark.parametrize('seed', range(5))
def test_tracker_with_noise_and_deadband(seed):
    x = sine(cycles=4) + np.random.default_rng(seed).normal(size=4 * PER) * NOISE
    tr = CycleTracker(DT, reversal_threshold=10 * NOISE)
    tr.reset(x[0])
    a, x0, f = tr.run(x)
    settled = slice(2 * PER, None)
    np.testing.assert_allclose(a[settled], A0, rtol=0.02)
    np.testing.assert_allclose(x0[settled], X0, rtol=0.02)
    np.testing.assert_allclose(f[settled], F0, rtol=0.02)
    assert tr.n_rev == 8                        # the noise made no reversals


@pytest.mark.parametrize('threshold', [0.0, 10 * NOISE])
def test_tracker_streaming_equals_batch_and_state_round_trip(threshold):
    # noise with d = 0 makes many short stretches (sample-by-sample path), a slow sine long ones (windows)
    rng = np.random.default_rng(7)
    x = np.concatenate([sine(cycles=3), sine(frequency=0.5, cycles=1.5)]) + rng.normal(size=3 * PER + 3000) * NOISE
    ref = CycleTracker(DT, reversal_threshold=threshold)
    ref.reset(0.0)
    streamed_out = np.array([ref.update(v) for v in x]).T
    tr = CycleTracker(DT, reversal_threshold=threshold)
    tr.reset(0.0)
    parts, i = [], 0
    for k in (1, 5, 64, 333, 2000, 10 ** 6):
        parts.append(np.array(tr.run(x[i:i + k])))
        i += k
    np.testing.assert_array_equal(np.concatenate(parts, axis=1), streamed_out)
    assert tr.get_state() == ref.get_state()
    # save mid-way, continue, restore into a fresh tracker: the same continuation
    tr.reset(0.0)
    tr.run(x[:1000])
    state = tr.get_state()
    first = np.array(tr.run(x[1000:]))
    other = CycleTracker(DT, reversal_threshold=threshold)
    other.set_state(state)
    np.testing.assert_array_equal(np.array(other.run(x[1000:])), first)
    np.testing.assert_array_equal(first, streamed_out[:, 1000:])
    with pytest.raises(ValueError, match='state'):
        other.set_state(state[:-1])


# --------------------------------------------------------------------------------------------------- damping

@pytest.mark.parametrize('b', [300.0, [[0.0, 1.128e6]]])   # constant, and seed 004's b ~ A
def test_elliptic_damping_steady_sine(b):
    x = sine(cycles=6)
    el = EllipticDamping(b, DT)
    el.reset(x[0])
    force = el.run(x)[0]
    b_val = trend_value(b, F0, A0)
    k_sim = harmonic_stiffness(x, force, PER)
    k_exact = el.complex_stiffness(F0, A0)
    assert k_exact.shape == (1,)
    assert k_exact[0] == pytest.approx(1j * b_val / A0, rel=1e-14)
    assert abs(k_sim - k_exact[0]) < 0.01 * abs(k_exact[0])
    # loop area pi b A (seed 004 Eq. 3), trapezoid over the last 4 cycles
    xs, fs = x[-4 * PER - 1:], force[-4 * PER - 1:]
    energy = np.sum(0.5 * (fs[1:] + fs[:-1]) * np.diff(xs)) / 4
    assert energy == pytest.approx(np.pi * b_val * A0, rel=0.01)
    # b cos(wt) = (b / (A w)) v: in phase with velocity, |F| <= b
    assert np.max(np.abs(force)) <= b_val * (1 + 1e-3)
    np.testing.assert_allclose(elliptic_first_harmonic(b, [2.0, 4.0], A0), 1j * b_val / A0, rtol=1e-14)


@pytest.mark.parametrize('threshold', [0.0, 10 * NOISE])
def test_elliptic_damping_streaming_equals_batch(threshold):
    x = sine(cycles=3) + np.random.default_rng(1).normal(size=3 * PER) * NOISE
    for el in (EllipticDamping([[0.0, 1.1e6], [1.0, 2e5]], DT, frequency=3.0, reversal_threshold=threshold),
               EllipticDamping(300.0, DT, amplitude=A0, center=X0, reversal_threshold=threshold)):
        np.testing.assert_array_equal(batched(el, x, X0), streamed(el, x, X0))
        el.reset(X0)
        el.run(x[:200])
        state = el.get_state()
        tail = el.run(x[200:])
        el.set_state(state)
        np.testing.assert_array_equal(el.run(x[200:]), tail)
    assert el.kinds == el.branch_names == ('viscous',)


def test_elliptic_damping_fixed_operating_point():
    b = 300.0
    el = EllipticDamping(b, DT, amplitude=A0, center=X0)
    x = sine(cycles=3)
    el.reset(X0)
    force = el.run(x)[0]
    # the paper's Eq. 4 at one operating point, from the first sample: no tracker transient
    s = np.sign(np.diff(np.concatenate(([X0], x))))
    for i in np.flatnonzero(s[1:] == 0) + 1:     # a zero increment (a tie at an extreme) keeps the direction
        s[i] = s[i - 1]
    np.testing.assert_allclose(force, s * b * np.sqrt(np.maximum(0, 1 - ((x - X0) / A0) ** 2)), rtol=1e-12, atol=0)
    assert el.complex_stiffness(F0, A0)[0] == pytest.approx(1j * b / A0, rel=1e-12)
    # a smaller or larger sine through the fixed ellipse: exact first harmonic against the time domain
    per = 1000
    for a_small in (0.25e-3, 0.8e-3):
        xs = sine(frequency=1.0, amplitude=a_small, cycles=3)
        el.reset(X0)
        fs = el.run(xs)[0]
        k = el.complex_stiffness(1.0, a_small)[0]
        # the force jumps by 2 b sqrt(1 - r^2) at a reversal found one sample late: O(dt f) = 0.3 % at r = 0.5
        assert abs(harmonic_stiffness(xs, fs, per, 2) - k) < 0.01 * abs(k)


# --------------------------------------------------------------------------------------------------- elastic

@pytest.mark.parametrize('mean', [0.0, X0])
@pytest.mark.parametrize('k_odd', [(0.0, 4.8e12), (0.0, 0.0, 3e18), (2.7e6, 4.8e12, 3e18)])
def test_odd_polynomial_first_harmonic_against_time_domain(k_odd, mean):
    x = sine(mean=mean, cycles=3)
    spring = OperatingPointSpring(k_odd, DT)
    spring.reset(x[0])
    force = spring.run(x)[0]
    k_sim = harmonic_stiffness(x, force, PER, cycles=3)
    k_exact = odd_polynomial_first_harmonic(k_odd, A0, mean)
    assert abs(k_sim - k_exact) < 0.005 * abs(k_exact)
    assert spring.complex_stiffness(F0, A0, mean=mean)[0] == pytest.approx(k_exact, rel=1e-12)


def test_first_harmonic_closed_forms():
    k1, k3, k5, k7 = 2.7e6, 4.8e12, 3e18, 1e24
    a = np.array([0.3e-3, 0.5e-3, 0.7e-3])
    np.testing.assert_allclose(odd_polynomial_first_harmonic((k1, k3, k5, k7), a),
                               k1 + 3 / 4 * k3 * a ** 2 + 10 / 16 * k5 * a ** 4 + 35 / 64 * k7 * a ** 6, rtol=1e-13)
    spring = OperatingPointSpring((k1, k3), DT)
    np.testing.assert_allclose(spring.complex_stiffness([2.0, 4.0, 6.0], a)[0], k1 + 0.75 * k3 * a ** 2, rtol=1e-13)
    # a general polynomial with a preload, against quadrature over the cycle (the even powers count too)
    coeffs = [5.0, 2e6, -3e9, 4.8e12, 1e15]
    mean = np.array([[0.0], [-0.9e-3], [-1.3e-3]])
    th = (np.arange(64) + 0.5) * 2 * np.pi / 64
    xq = mean[..., None] + a[:, None] * np.sin(th)
    quad = (np.polynomial.polynomial.polyval(xq, coeffs) * np.sin(th)).mean(-1) * 2 / a
    got = polynomial_first_harmonic(coeffs, a, mean)
    assert got.shape == (3, 3) and np.iscomplexobj(got)
    np.testing.assert_allclose(got.real, quad, rtol=1e-12)
    # vanishing amplitude: the tangent stiffness P'(m)
    assert polynomial_first_harmonic(coeffs, 0.0, -1e-3).real == pytest.approx(
        np.polynomial.polynomial.polyval(-1e-3, np.polynomial.polynomial.polyder(coeffs)), rel=1e-12)


def test_spring_coefficients_follow_the_amplitude():
    k1 = [[4.6e6, -3e9]]                       # K1 = 4.6e6 - 3e9 A [N/m] (A in m)
    spring = OperatingPointSpring([k1, 4.8e12], DT, amplitude=0.5e-3)
    for amp in (0.3e-3, 0.7e-3):
        x = sine(amplitude=amp, cycles=3)
        spring.reset(x[0])
        force = spring.run(x)[0]
        late = slice(2 * PER, None)
        k1_seen = (force[late] - 4.8e12 * x[late] ** 3) / x[late]
        np.testing.assert_allclose(k1_seen, 4.6e6 - 3e9 * amp, rtol=1e-3)
        assert spring.coefficients(F0, amp)[0] == pytest.approx(4.6e6 - 3e9 * amp, rel=1e-14)
    # before two reversals the default amplitude is used
    spring.reset(X0)
    assert spring.step(X0)[0] == pytest.approx((4.6e6 - 3e9 * 0.5e-3) * X0 + 4.8e12 * X0 ** 3, rel=1e-14)


def test_spring_streaming_equals_batch():
    spec = seed004_pad_spec()
    x = sine(cycles=3) + np.random.default_rng(2).normal(size=3 * PER) * NOISE
    for threshold in (0.0, 10 * NOISE):
        spring = OperatingPointSpring(spec['k_odd'], DT, frequency=F0, reversal_threshold=threshold)
        np.testing.assert_array_equal(batched(spring, x), streamed(spring, x))
    assert spring.kinds == spring.branch_names == ('elastic',)


# ---------------------------------------------------------------------------------------------- seed 004 data

# seed 004 Table 2: (f [Hz], A [mm]) -> (K1 [kN/mm], K3 [kN/mm^3])
TABLE2 = {(2, 0.3): (2.74, 4.62), (6, 0.3): (2.45, 4.80), (8, 0.3): (2.37, 4.87), (10, 0.3): (2.33, 4.95),
          (2, 0.5): (1.74, 5.06), (6, 0.5): (1.44, 5.22), (8, 0.5): (1.41, 5.26), (10, 0.5): (1.35, 5.32),
          (2, 0.7): (0.92, 4.46), (6, 0.7): (0.80, 4.56), (8, 0.7): (0.78, 4.59), (10, 0.7): (0.73, 4.60)}
# seed 004 Table 3: f [Hz] -> (a0, a1, a2) of K1 = a0 + a1 A + a2 A^2 (kN/mm, A in mm)
TABLE3 = {2: (4.594, -6.854, 2.292), 6: (4.677, -8.815, 4.687), 8: (4.471, -8.270, 4.289), 10: (4.457, -8.438, 4.448)}
# seed 004 Eq. 9 and Eq. 12 as printed: b[i][j] for f^i [Hz], A^j [mm]
EQ9 = [[3.77, -1.75, -2.93], [0.61, -3.56, -3.59], [-0.11, 0.56, -0.54], [0.01, -0.03, 0.03]]
EQ12 = [[2.11, 11.28, -11.43], [-0.08, 0.87, -1.03], [0.02, -0.15, 0.07], [0.0, 0.01, -0.01]]
ROUNDING = 0.005    # half the last printed digit of Table 2 [kN/mm, kN/mm^3]


def test_seed004_pad_reproduces_table2():
    spec = seed004_pad_spec()
    k1, k3 = spec['k_odd']
    for (f, a), (k1_paper, k3_paper) in TABLE2.items():
        # 1 kN/mm = 1e6 N/m, 1 kN/mm^3 = 1e12 N/m^3; A [mm] -> [m]
        assert abs(trend_value(k1, f, a * 1e-3) / 1e6 - k1_paper) <= ROUNDING, (f, a)
        assert abs(trend_value(k3, f, a * 1e-3) / 1e12 - k3_paper) <= ROUNDING, (f, a)
        # an interpolant: exact up to round-off, not only within the rounding
        assert trend_value(k3, f, a * 1e-3) == pytest.approx(k3_paper * 1e12, rel=1e-12)
        assert trend_value(k1, f, a * 1e-3) == pytest.approx(k1_paper * 1e6, rel=1e-12)
    assert trend_value(spec['b'], 2.0, 0.3e-3) == pytest.approx(338.5, rel=1e-12)   # Fig. 5: P4 = 0.3385 kN
    assert trend_value(spec['b'], 2.0, 0.6e-3) == pytest.approx(677.0, rel=1e-12)   # b ~ A
    assert spec['preloads'] == [-0.9e-3, -1.1e-3, -1.3e-3]
    assert spec['amplitudes'] == [0.3e-3, 0.5e-3, 0.7e-3]


def test_seed004_k3_rises_with_frequency():
    # Table 2 (and the paper's Section 4.2): K3 rises with f at every amplitude, K1 falls
    k1, k3 = seed004_pad_spec()['k_odd']
    f = np.array([2.0, 6.0, 8.0, 10.0])
    for a in (0.3e-3, 0.5e-3, 0.7e-3):
        assert np.all(np.diff(trend_value(k3, f, a)) > 0), a
        assert np.all(np.diff(trend_value(k1, f, a)) < 0), a
    # and 4 Hz (Table 1, no Table 2 row) lies between 2 and 6 Hz
    for a in (0.3e-3, 0.5e-3, 0.7e-3):
        assert trend_value(k3, 2.0, a) < trend_value(k3, 4.0, a) < trend_value(k3, 6.0, a)
    with pytest.raises(ValueError, match='frequency'):   # K3 depends on f now: the spring needs a default f
        OperatingPointSpring([k1, k3], DT)
    with pytest.raises(ValueError, match='frequency'):
        OperatingPointSpring([1e6, k3], DT)


def test_seed004_table3_cross_check():
    # Table 3 is K1's quadratic in A per frequency, fitted before Table 2 was rounded: its quadratics meet the
    # interpolant at the 12 points within Table 2's rounding plus Table 3's (0.0005 (1 + A + A^2) <= 0.0011), and
    # (8 Hz, 0.3 mm) misses that by 0.0003 (2.376 against 2.37): the two tables disagree there, hence 0.0065
    k1 = seed004_pad_spec()['k_odd'][0]
    worst = 0.0
    for (f, a), _ in TABLE2.items():
        a0, a1, a2 = TABLE3[f]
        worst = max(worst, abs(trend_value(k1, f, a * 1e-3) / 1e6 - (a0 + a1 * a + a2 * a * a)))
    assert 0.0055 < worst <= 0.0065
    # the interpolant's a_i at each frequency against Table 3's: within Table 2's rounding carried through the
    # quadratic (sum_k |L_ik| 0.005: 0.058, 0.25, 0.25), not to Table 3's printed digits
    amps = np.array([0.3, 0.5, 0.7])
    inv = np.linalg.inv(np.vander(amps, 3, increasing=True))
    bound = np.abs(inv).sum(axis=1) * ROUNDING + 0.0005
    for f, a_paper in TABLE3.items():
        a_interp = inv @ (trend_value(k1, float(f), amps * 1e-3) / 1e6)
        assert np.all(np.abs(a_interp - a_paper) <= bound), (f, a_interp, a_paper)
    # Table 3's a_i fitted by a cubic in f is Eq. 9 with +3.587 where Eq. 9 prints -3.59
    b_fit = np.linalg.solve(np.vander([2.0, 6.0, 8.0, 10.0], 4, increasing=True), np.array(list(TABLE3.values())))
    assert b_fit[1, 2] == pytest.approx(3.587, abs=5e-4)
    assert np.all(np.abs(np.delete(b_fit.ravel(), 5) - np.delete(np.ravel(EQ9), 5)) <= 0.005 + 1e-9)


def test_seed004_printed_equations_miss_table2():
    """The figures quoted in seed004_pad_spec and REFERENCES.md: Eq. 10-12 as printed against Table 2."""
    def miss(b, column):
        worst = (0.0, None)
        for (f, a), values in TABLE2.items():
            v = np.polynomial.polynomial.polyval2d(f, a, np.asarray(b))
            if abs(v - values[column]) > abs(worst[0]):
                worst = (v - values[column], (f, a), values[column])
        return worst

    eq9_fixed = [row[:] for row in EQ9]
    eq9_fixed[1][2] = 3.59
    err, point, paper = miss(EQ9, 0)
    assert err == pytest.approx(-30.59, abs=0.01) and point == (10, 0.7)          # -29.86 for 0.73 kN/mm
    err, point, paper = miss(eq9_fixed, 0)
    assert err == pytest.approx(4.59, abs=0.01) and point == (10, 0.7)            # 5.32 for 0.73 kN/mm
    err, point, paper = miss(EQ12, 1)
    assert err == pytest.approx(-2.92, abs=0.01) and point == (10, 0.7)           # 1.68 for 4.60 kN/mm^3
    assert err / paper == pytest.approx(-0.635, abs=0.001)


def test_seed004_table2_check():
    rows = seed004_table2_check()
    assert [(r['frequency'], round(r['amplitude'] * 1e3, 6)) for r in rows] == list(TABLE2)
    preload = {0.3: -0.9e-3, 0.5: -1.1e-3, 0.7: -1.3e-3}             # Table 1
    for r in rows:
        f, a, x0 = r['frequency'], r['amplitude'], r['preload']
        assert x0 == pytest.approx(preload[round(a * 1e3, 6)], rel=1e-12)
        # the first harmonic about x0 of K1 x + K3 x^3: K1 + 3 K3 x0^2 + 3/4 K3 A^2
        k_op = r['K1_table'] + 3 * r['K3_table'] * x0 ** 2 + 0.75 * r['K3_table'] * a ** 2
        assert r['K_op_table'] == pytest.approx(k_op, rel=1e-12)
        assert abs(r['K_op_error']) < 1e-12
        # K_sim carries the tracker's estimated (f, A). With no deadband the half period is measured between
        # extreme samples, +-1 sample: |df| <= 2 f^2 dt (0.2 Hz at 10 Hz), and |d ln K_op / df| <= 0.7 %/Hz on
        # the table, so <= 0.14 %; the amplitude, read at a sample <= dt/2 from the peak, is low by <= (pi f dt)^2 / 8
        # = 1.2e-4 relative, times d ln K_op / d ln A <= 0.9. Tolerance 0.2 %; observed <= 0.01 %.
        assert abs(r['K_sim'] / r['K_op'] - 1) < 2e-3, (f, a)
    # the pad stiffens with f at every amplitude, as Table 2's does
    for a in (0.3e-3, 0.5e-3, 0.7e-3):
        k = [r['K_op'] for r in rows if r['amplitude'] == a]
        assert np.all(np.diff(k) > 0), a


def test_seed004_pad_runs_under_preload():
    spec = seed004_pad_spec()
    f, a, mean = 2.0, 0.3e-3, spec['preloads'][0]
    per = int(round(1 / (f * DT)))
    x = sine(frequency=f, amplitude=a, mean=mean, cycles=4)
    spring = OperatingPointSpring(spec['k_odd'], DT, frequency=f, amplitude=a)
    damper = EllipticDamping(spec['b'], DT)
    for el in (spring, damper):
        el.reset(x[0])
    fk, fc = spring.run(x)[0], damper.run(x)[0]
    # compression: x < 0 gives F_k < 0, about -6.0 kN mean at the -0.9 mm preload: the cycle mean of
    # K1 x + K3 x^3 is K1 m + K3 (m^3 + 3/2 m A^2), K1 = 2.74e6 N/m, K3 = 4.62e12 N/m^3 (Table 2)
    assert np.all(fk < 0)
    assert np.mean(fk[-per:]) == pytest.approx(2.74e6 * mean + 4.62e12 * (mean ** 3 + 1.5 * mean * a ** 2),
                                               rel=0.01)
    k_elastic = harmonic_stiffness(x, fk, per, 2)
    k1, k3 = spring.coefficients(f, a)
    assert k_elastic == pytest.approx(odd_polynomial_first_harmonic((k1, k3), a, mean), rel=0.01)
    assert harmonic_stiffness(x, fc, per, 2) == pytest.approx(1j * 338.5 / a, rel=0.01)
