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

from rubber_rig.models.pad import (
    AMPLITUDE_FLOOR,
    CycleTracker,
    EllipticDamping,
    OperatingPointSpring,
    check_trend,
    elliptic_first_harmonic,
    odd_polynomial_first_harmonic,
    polynomial_first_harmonic,
    seed004_pad_spec,
    trend_value,
)

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

def test_seed004_pad_spec_against_tables():
    spec = seed004_pad_spec()
    k1, k3 = spec['k_odd']
    # seed 004 Table 2: K1 [kN/mm] at (f [Hz], A [mm])
    table2 = {(2, 0.3): 2.74, (6, 0.3): 2.45, (8, 0.3): 2.37, (10, 0.3): 2.33,
              (2, 0.5): 1.74, (6, 0.5): 1.44, (8, 0.5): 1.41, (10, 0.5): 1.35,
              (2, 0.7): 0.92, (6, 0.7): 0.80, (8, 0.7): 0.78, (10, 0.7): 0.73}
    for (f, a), k in table2.items():
        assert trend_value(k1, f, a * 1e-3) == pytest.approx(k * 1e6, rel=0.10), (f, a)
    # the two the brief names are reproduced closely (Table 3 is Table 2's quadratic in A)
    assert trend_value(k1, 2.0, 0.3e-3) == pytest.approx(2.74e6, rel=0.005)
    assert trend_value(k1, 10.0, 0.7e-3) == pytest.approx(0.73e6, rel=0.005)
    assert k3 == pytest.approx(4.8e12, rel=0.05)                     # 1 kN/mm^3 = 1e12 N/m^3
    assert trend_value(spec['b'], 2.0, 0.3e-3) == pytest.approx(338.5, rel=1e-12)   # Fig. 5: P4 = 0.3385 kN
    assert trend_value(spec['b'], 2.0, 0.6e-3) == pytest.approx(677.0, rel=1e-12)   # b ~ A
    assert spec['preloads'] == [-0.9e-3, -1.1e-3, -1.3e-3]


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
    # compression: x < 0 gives F_k < 0, about -6.6 kN mean at the -0.9 mm preload: the cycle mean of
    # K1 x + K3 x^3 is K1 m + K3 (m^3 + 3/2 m A^2), K1 = 2.744e6 N/m (Table 2: 2.74 kN/mm)
    assert np.all(fk < 0)
    k3 = spec['k_odd'][1]
    assert np.mean(fk[-per:]) == pytest.approx(2.744e6 * mean + k3 * (mean ** 3 + 1.5 * mean * a ** 2), rel=0.01)
    k_elastic = harmonic_stiffness(x, fk, per, 2)
    k1, k3 = spring.coefficients(f, a)
    assert k_elastic == pytest.approx(odd_polynomial_first_harmonic((k1, k3), a, mean), rel=0.01)
    assert harmonic_stiffness(x, fc, per, 2) == pytest.approx(1j * 338.5 / a, rel=0.01)
