"""Berg friction (seed 000 Eq. 16-22) and smooth Coulomb friction (seed 002)."""
import numpy as np
import pytest

from rubber_rig.models import (BergFriction, SmoothCoulomb, berg_force, berg_steady_state, build_model,
                               load_parameter_set, sine_displacement, steady_state_properties)

P20 = load_parameter_set('seed000_20C')
FM, X2 = P20.f_fmax, P20.x2


def loop(element, amplitude, samples_per_cycle=4000, cycles=150):
    element.reset()
    dt = element.dt
    x = sine_displacement(1.0 / (samples_per_cycle * dt), amplitude, dt, cycles)
    f = element.run(x)[0]
    last = slice(-(samples_per_cycle + 1), None)
    return x[last], f[last]


def test_eq16_virgin_curve():
    x = np.array([X2, 1e3 * X2, -X2, -1e3 * X2, 0.0])
    f = berg_force(x, 0.0, 0.0, FM, X2)
    np.testing.assert_allclose(f[:4], [FM / 2, FM * 1e3 / 1001, -FM / 2, -FM * 1e3 / 1001], rtol=1e-12)
    assert f[4] == 0.0
    # tangent stiffness right after any reference state is F_fmax / x2
    for fs in (-0.8 * FM, 0.0, 0.5 * FM):
        d = 1e-9
        assert (berg_force(1e-4 + d, 1e-4, fs, FM, X2) - fs) / d == pytest.approx(FM / X2, rel=1e-5)


@pytest.mark.parametrize('amplitude', [0.2e-3, 0.5e-3, 1e-3, 3e-3])
def test_eq17_eq18_against_simulated_steady_loop(amplitude):
    e = BergFriction(FM, X2, dt=1e-3)
    x, f = loop(e, amplitude)
    ss = berg_steady_state(amplitude, FM, X2)
    assert 0.5 * (f.max() - f.min()) == pytest.approx(ss['f_f0'], rel=1e-5)
    area = np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(x))
    assert area == pytest.approx(ss['energy'], rel=2e-3)   # trapezoid at 4000 samples/cycle
    # Eq. 19-22 consistency
    assert ss['k_df'] == pytest.approx(ss['f_f0'] / amplitude)
    assert ss['d_f'] == pytest.approx(ss['energy'] / (np.pi * ss['f_f0'] * amplitude))
    assert np.hypot(ss['k_fs'], ss['k_fl']) == pytest.approx(ss['k_df'])


def test_loop_settles_from_the_virgin_state():
    """From (0, 0) the loop starts asymmetric and converges geometrically to Eq. 17 (~20 cycles)."""
    e = BergFriction(FM, X2, dt=1e-3)
    x = sine_displacement(1.0, 1e-3, 1e-3, 30)
    f = e.run(x)[0]
    f0 = berg_steady_state(1e-3, FM, X2)['f_f0']
    first, last = f[:1001], f[-1001:]
    assert first.max() > 1.1 * f0                      # virgin overshoot
    assert abs(last.max() - f0) < 1e-5 * f0 and abs(last.min() + f0) < 1e-5 * f0


def test_reversal_updates_reference_state():
    e = BergFriction(FM, X2, dt=1e-3)
    up = np.linspace(0, 1e-3, 11)[1:]
    down = np.linspace(1e-3, 0, 11)[1:]
    fu = e.run(up)[0]
    assert e.x_s == 0.0 and e.f_s == 0.0
    fd = e.run(down)[0]
    assert e.x_s == pytest.approx(1e-3) and e.f_s == pytest.approx(fu[-1])
    assert fd[0] < fu[-1]                                   # force falls right after reversal
    ref = berg_force(down, 1e-3, fu[-1], FM, X2)
    np.testing.assert_allclose(fd, ref, rtol=1e-12)
    # pauses (zero increments) do not count as reversals
    e.reset()
    e.run(np.array([1e-4, 2e-4, 2e-4, 2e-4, 3e-4]))
    assert e.x_s == 0.0 and e.direction == 1


@pytest.mark.parametrize('kind', ['sine', 'noise', 'plateaus'])
def test_berg_streaming_equals_batch_and_chunks(kind):
    rng = np.random.default_rng(7)
    n = 4000
    if kind == 'sine':
        x = 1e-3 * np.sin(2 * np.pi * 3 * np.arange(n) * 1e-3)
    elif kind == 'noise':
        x = rng.normal(size=n) * 1e-4 + 5e-4 * np.sin(np.arange(n) * 0.01)
    else:
        x = np.round(1e-3 * np.sin(np.arange(n) * 0.005) * 2e4) / 2e4
    e = BergFriction(FM, X2, 1e-3)
    full = e.run(x)[0]
    e.reset()
    stream = np.array([e.step(v)[0] for v in x])
    e.reset()
    cuts = np.sort(rng.choice(np.arange(1, n), size=40, replace=False))
    chunks = np.concatenate([e.run(c)[0] for c in np.split(x, cuts)])
    np.testing.assert_allclose(stream, full, rtol=0, atol=1e-12 * FM)
    np.testing.assert_allclose(chunks, full, rtol=0, atol=1e-12 * FM)


def test_vanishing_friction_leaves_the_viscoelastic_model():
    d = P20.as_dict()
    d['f_fmax'] = 1e-9
    m = build_model({'model': 'seed000', 'values': d}, 1e-3)
    x = sine_displacement(2.0, 1e-3, 1e-3, 3)
    total, br = m.run(x, return_branches=True)
    assert np.abs(br[2]).max() <= 1e-9
    np.testing.assert_allclose(total, br[0] + br[1], rtol=0, atol=2e-9)
    s = steady_state_properties(m, 2.0, 1e-3)
    from rubber_rig.models import zener_complex_stiffness
    kz = zener_complex_stiffness(2 * np.pi * 2.0, P20.k0, P20.k_inf, P20.tau, P20.alpha)
    assert s['k_dyn'] == pytest.approx(abs(kz), rel=1e-9)
    assert s['energy_friction'] < 1e-12


def test_smooth_coulomb_time_vs_describing_function_and_coulomb_limit():
    fc, a, x0, f = 500.0, 50.0, 1e-3, 2.0
    e = SmoothCoulomb(fc, a, dt=1e-4)
    x = sine_displacement(f, x0, 1e-4, 3)
    force = e.run(x)[0]
    n = int(round(1 / (f * 1e-4)))
    energy = np.sum(0.5 * (force[-n - 1:][1:] + force[-n - 1:][:-1]) * np.diff(x[-n - 1:]))
    kl = e.complex_stiffness(f, x0)[0].imag
    assert energy == pytest.approx(np.pi * x0 ** 2 * kl, rel=5e-3)
    steep = SmoothCoulomb(fc, 1e6, dt=1e-4)
    # Coulomb limit: E = 4 F x0, loss stiffness 4 F / (pi x0)
    assert steep.complex_stiffness(f, x0)[0].imag == pytest.approx(4 * fc / (np.pi * x0), rel=1e-3)
    e.reset()
    stream = np.array([e.step(v)[0] for v in x[:500]])
    e.reset()
    np.testing.assert_allclose(stream, e.run(x[:500])[0], rtol=1e-14)
