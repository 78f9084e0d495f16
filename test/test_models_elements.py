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

"""Elastic/viscous elements, parallel composition, model object contract."""
import copy

import numpy as np
import pytest

from rubber_rig.analysis import harmonic_properties
from rubber_rig.models import (
    Dashpot,
    Maxwell,
    PolynomialSpring,
    TangentMaxwellBergParams,
    TangentSpring,
    build_model,
    load_parameter_set,
    sine_displacement,
    steady_state_properties,
)

P20 = load_parameter_set('seed000_20C')
S001 = TangentMaxwellBergParams(k_t=2.0e6, d_t=6e-3, k1=1.0e6, c1=2.0e4, k2=0.5e6, c2=1.0e3, f_fmax=300.0, x2=0.3e-3)


def steady(element_or_model, f, x0, dt, cycles=5):
    element_or_model.reset()
    x = sine_displacement(f, x0, dt, cycles)
    out = element_or_model.run(x)
    force = out if out.ndim == 1 else out.sum(axis=0)
    n = int(round(1 / (f * dt))) + 1
    return harmonic_properties(x[-n:], force[-n:], dt, f)


@pytest.mark.parametrize('f', [0.5, 5.0, 40.0])
def test_maxwell_time_vs_analytic(f):
    k, c = 1.0e6, 2.0e4
    e = Maxwell(k, c, dt=2e-4)
    h = steady(e, f, 1e-3, 2e-4, cycles=int(max(5, 10 * f * c / k)) + 3)
    ke = e.complex_stiffness(f, 1e-3)[0]
    k1 = h.k_dyn * np.exp(1j * h.loss_angle)
    # FOH discretisation: storage and loss within (w h)^2/12 + margin
    tol = (2 * np.pi * f * 2e-4) ** 2 / 12 + 1e-4
    assert abs(k1.real / ke.real - 1) < tol and abs(k1.imag / ke.imag - 1) < tol


def test_dashpot_and_kelvin_voigt_case1():
    kv = build_model('seed000_case1', dt=1e-4)
    assert kv.branch_names == ('elastic', 'viscous')
    f, x0 = 0.5, 1e-3
    h = steady(kv, f, x0, 1e-4, cycles=2)
    s = steady_state_properties('seed000_case1', f, x0)
    assert s['c_eq'] == pytest.approx(243e3, rel=1e-12)          # KV: C_eq is c (Eq. 27)
    assert s['k_dyn'] == pytest.approx(np.hypot(14e6, 2 * np.pi * f * 243e3), rel=1e-12)
    # backward-difference velocity: half-sample lag, first-order in w h
    assert h.k_dyn == pytest.approx(s['k_dyn'], rel=1e-3)
    assert h.c_eq == pytest.approx(243e3, rel=1e-3)
    d = Dashpot(100.0, 1e-3)
    assert d.step(1e-3)[0] == pytest.approx(100.0)


def test_polynomial_springs():
    p = PolynomialSpring([10.0, 2.0e6, 0.0, 5.0e11])
    x = np.linspace(-1e-3, 1e-3, 7)
    np.testing.assert_allclose(p.run(x)[0], 10 + 2e6 * x + 5e11 * x ** 3, rtol=1e-13)
    assert p.step(1e-3)[0] == pytest.approx(10 + 2e3 + 5e2)
    odd = PolynomialSpring.odd([2.0e6, 5.0e11, 1.0e17])   # seed 004 Eq. 5: K1 x + K3 x^3 + K5 x^5
    x0 = 0.5e-3
    assert odd.force(x0) == pytest.approx(2e6 * x0 + 5e11 * x0 ** 3 + 1e17 * x0 ** 5)
    assert odd.force(-x0) == pytest.approx(-odd.force(x0))
    k = odd.complex_stiffness(1.0, x0)[0]
    assert k.imag == 0 and k.real == pytest.approx(odd.force(x0) / x0)   # seed 003 Eq. 5 peak convention


def test_tangent_spring():
    t = TangentSpring(k_t=2e6, d_t=5e-3)
    assert (t.force(1e-7) / 1e-7) == pytest.approx(2e6, rel=1e-6)           # slope k_t at 0
    assert t.force(2.5e-3) == pytest.approx(2 * 2e6 * 5e-3 / np.pi * np.tan(np.pi / 4))
    assert t.force(4.9e-3) > 10 * 2e6 * 4.9e-3 / 5                        # stiffening towards d_t
    with pytest.raises(ValueError, match='d_t'):
        t.step(5e-3)
    with pytest.raises(ValueError, match='d_t'):
        t.run(np.array([0.0, 6e-3]))


def test_seed001_combined_model():
    m = build_model({'model': 'seed001', 'values': S001.as_dict()}, dt=5e-4)
    assert m.branch_names == ('elastic', 'viscous_1', 'viscous_2', 'friction')
    assert m.branch_kinds == ('elastic', 'viscous', 'viscous', 'friction')
    s = steady_state_properties(m, 10.0, 1e-3)
    r = __import__('rubber_rig.models', fromlist=['x']).time_domain_properties(m, 10.0, 1e-3, cycles=60)
    # the analytic model treats friction and the tangent spring by their peak-force equivalents
    assert r['k_dyn'] == pytest.approx(s['k_dyn'], rel=0.03)
    assert r['energy'] == pytest.approx(s['energy'], rel=0.01)
    assert r['energy_viscous'] == pytest.approx(s['energy_viscous'], rel=0.01)


def test_parallel_spec_and_branch_sum():
    spec = {'model': 'parallel', 'elements': [
        {'type': 'linear_spring', 'k': 1e6}, {'type': 'maxwell', 'k': 2e5, 'c': 1e3},
        {'type': 'fractional_zener', 'k0': 1e6, 'k_inf': 2e6, 'tau': 0.01, 'alpha': 0.5},
        {'type': 'berg', 'f_fmax': 100.0, 'x2': 1e-4}, {'type': 'smooth_coulomb', 'f_c': 20.0, 'a': 10.0},
        {'type': 'polynomial_spring', 'k3': 1e10},
        {'type': 'two_order_fractional', 'k1': 1e5, 'k2': 5e4, 'c1': 2e3, 'c2': 1e3, 'alpha': 0.5, 'beta': 0.8},
        {'type': 'dashpot', 'c': 10.0}, {'type': 'tangent_spring', 'k_t': 1e5, 'd_t': 0.01},
        {'type': 'zener', 'k0': 1e5, 'k_inf': 2e5, 'tau': 0.1}]}
    m = build_model(spec, 1e-3)
    assert len(m.branch_names) == len(set(m.branch_names)) == m.last_branches.size
    x = 1e-3 * np.sin(np.arange(800) * 0.02) + np.random.default_rng(2).normal(size=800) * 1e-5
    total, br = m.run(x, return_branches=True)
    assert br.shape == (len(m.branch_names), x.size)
    np.testing.assert_allclose(total, br.sum(axis=0), rtol=1e-14, atol=1e-9)
    np.testing.assert_allclose(m.last_branches, br[:, -1])
    m.reset()
    stream = np.array([m.step(v) for v in x])
    np.testing.assert_allclose(stream, total, rtol=0, atol=1e-11 * np.abs(total).max())


def test_state_save_restore_and_reset():
    m = build_model(P20, 1e-3)
    x = 1e-3 * np.sin(2 * np.pi * 2 * np.arange(3000) * 1e-3)
    m.run(x[:1234])
    snap = m.get_state()
    a = m.run(x[1234:])
    m.run(x[:50])                        # move on, then go back
    m.set_state(snap)
    b = np.array([m.step(v) for v in x[1234:]])
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-11 * np.abs(a).max())
    snap2 = copy.deepcopy(m.get_state())
    m.step(1.0)
    assert m.get_state()[0][1] != snap2[0][1]    # snapshot is a copy, not a view
    m.reset()
    fresh = build_model(P20, 1e-3)
    np.testing.assert_array_equal(m.run(x[:100]), fresh.run(x[:100]))
    # reset(x0): relaxed at a preload, no force transient from the viscous branch
    m.reset(2e-3)
    f = m.run(np.full(100, 2e-3), return_branches=True)[1]
    np.testing.assert_allclose(f[0], P20.k0 * 2e-3)
    assert np.abs(f[1]).max() < 1e-6 and np.abs(f[2]).max() == 0.0


def test_run_validates_shape():
    m = build_model(P20, 1e-3)
    with pytest.raises(ValueError, match='1-D'):
        m.run(np.zeros((2, 3)))
    assert m.run(np.zeros(0)).shape == (0,)
