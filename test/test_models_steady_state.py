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

"""Analytic steady state (seed 000 Eq. 23-27, 30) and its agreement with the time domain."""
import numpy as np
import pytest

from rubber_rig.models import (
    berg_steady_state,
    build_model,
    load_parameter_set,
    steady_state_properties,
    time_domain_properties,
    zener_complex_stiffness,
)
from rubber_rig.models.composite import ParallelModel
from rubber_rig.models.elements import LinearSpring, PolynomialSpring
from rubber_rig.models.friction import friction_first_harmonic
from rubber_rig.models.modelfile import spec_from_params
from rubber_rig.models.simulate import whole_cycle_dt

P20, P40 = load_parameter_set('seed000_20C'), load_parameter_set('seed000_m40C')
KEYS = ('frequency', 'amplitude', 'k_dyn', 'loss_angle', 'damping', 'c_eq', 'energy', 'r_k', 'r_e')


def test_composition_equations():
    f, x0 = 4.0, 0.5e-3
    s = steady_state_properties(P20, f, x0, kdyn='eq24')
    assert set(KEYS) <= set(s) and s['kdyn_definition'] == 'eq24'
    assert steady_state_properties(P20, f, x0)['kdyn_definition'] == 'harmonic'         # the default, as the CLI
    kz = zener_complex_stiffness(2 * np.pi * f, P20.k0, P20.k_inf, P20.tau, P20.alpha)
    b = berg_steady_state(x0, P20.f_fmax, P20.x2)
    k_s, k_l = kz.real + b['k_fs'], kz.imag + b['k_fl']
    assert s['k_dyn'] == pytest.approx(np.hypot(k_s, k_l), rel=1e-12)                 # Eq. 24
    e_v = np.pi * x0 ** 2 * kz.imag                                                     # Eq. 25
    assert s['energy'] == pytest.approx(e_v + b['energy'], rel=1e-12)
    assert s['damping'] == pytest.approx(s['energy'] / (np.pi * x0 ** 2 * s['k_dyn']), rel=1e-12)  # Eq. 26
    assert s['c_eq'] == pytest.approx(s['energy'] / (np.pi * 2 * np.pi * f * x0 ** 2), rel=1e-12)  # Eq. 27
    assert np.sin(s['loss_angle']) == pytest.approx(s['damping'], rel=1e-12)           # Eq. 3
    assert s['r_k'] == pytest.approx(abs(kz - P20.k0) / b['k_df'], rel=1e-12)           # Eq. 30
    assert s['r_e'] == pytest.approx(e_v / b['energy'], rel=1e-12)


def test_broadcasting():
    f = np.array([0.5, 2.0, 8.0])[:, None]
    a = np.array([0.5e-3, 1e-3])
    s = steady_state_properties(P20, f, a)
    assert s['k_dyn'].shape == (3, 2)
    assert s['k_dyn'][1, 0] == pytest.approx(steady_state_properties(P20, 2.0, 0.5e-3)['k_dyn'], rel=1e-12)
    assert isinstance(steady_state_properties(P20, 2.0, 1e-3)['k_dyn'], float)


def test_paper_trends():
    """Seed 000 Sections 3-4: K_dyn rises with frequency, falls with amplitude; cold is stiffer and
    more viscous (R_K, R_E > 1 at -40 degC and 14 Hz, < 1 at 20 degC and 0.5 Hz), with the paper's Eq. 24."""
    f = np.array([0.5, 2, 4, 8, 14])
    s = steady_state_properties(P20, f, 0.5e-3, kdyn='eq24')
    assert np.all(np.diff(s['k_dyn']) > 0) and np.all(np.diff(s['c_eq']) < 0)
    assert np.all(steady_state_properties(P20, f, 1e-3, kdyn='eq24')['k_dyn'] < s['k_dyn'])
    assert np.all(steady_state_properties(P40, f, 0.5e-3, kdyn='eq24')['k_dyn'] > s['k_dyn'])
    cold = steady_state_properties(P40, 14.0, 1e-3, kdyn='eq24')
    warm = steady_state_properties(P20, 0.5, 0.5e-3, kdyn='eq24')
    assert cold['r_k'] > 1 and cold['r_e'] > 1 and warm['r_k'] < 1 and warm['r_e'] < 1


@pytest.mark.parametrize('p,f,x0', [(P20, 0.5, 1e-3), (P20, 4.0, 0.5e-3), (P40, 14.0, 0.5e-3)])
def test_time_domain_matches_analytic(p, f, x0):
    m = build_model(p, 1e-3)
    r = time_domain_properties(m, f, x0)
    s = steady_state_properties(p, f, x0, kdyn='harmonic')
    assert r['kdyn_definition'] == 'harmonic'
    # the time run measures the first harmonic: the same definition as kdyn='harmonic' for every key.
    # What is left is the discretisation of the fractional scheme (0.1 % at 14 Hz, 71 samples per cycle)
    # and of Berg's sampled reversals
    assert r['k_dyn'] == pytest.approx(s['k_dyn'], rel=2e-3)
    assert r['damping'] == pytest.approx(s['damping'], rel=3e-3)
    assert r['energy'] == pytest.approx(s['energy'], rel=3e-3)
    assert r['energy_friction'] == pytest.approx(s['energy_friction'], rel=1e-3)
    assert r['energy_viscous'] == pytest.approx(s['energy_viscous'], rel=5e-3)
    assert r['k_df'] == pytest.approx(s['k_df'], rel=1e-3)          # |first harmonic of the friction force|
    assert r['r_e'] == pytest.approx(s['r_e'], rel=5e-3)
    assert r['r_k'] == pytest.approx(s['r_k'], rel=5e-3)
    # Eq. 19's K_df is the friction peak force over x0: the eq24 definition's k_df
    assert r['k_df_peak'] == pytest.approx(steady_state_properties(p, f, x0, kdyn='eq24')['k_df'], rel=1e-3)


@pytest.mark.parametrize('whole', [True, False])
def test_time_domain_first_harmonic_at_the_reported_point(whole):
    """Issue: 1.3 Hz at 1 kHz is 769.23 samples per cycle; the last 2 cycles were rounded down to one and
    the drift column of the harmonic fit leaked the friction loop's odd harmonics: K_dyn +0.87 % at -40 degC,
    1 mm. Now: the window is 2 whole cycles (exactly, at whole_cycle_dt: 769 samples per cycle), the fit has
    no drift column. Measured: -0.0063 % (the fractional scheme's own discretisation), tolerance 0.02 %."""
    p, f, x0 = load_parameter_set('swing_arm_joint_m40C'), 1.3, 1e-3
    dt = whole_cycle_dt(f, 1000.0) if whole else 1e-3
    r = time_domain_properties(build_model(p, dt), f, x0)
    s = steady_state_properties(p, f, x0, kdyn='harmonic')
    assert r['k_dyn'] == pytest.approx(s['k_dyn'], rel=2e-4)
    assert r['loss_angle'] == pytest.approx(s['loss_angle'], abs=1e-3)
    assert r['cycles_analysed'] == 2
    # the friction branch alone has no scheme error: its first harmonic is exact up to the sampled reversal
    # (1.3e-6 at 769 whole samples per cycle, 1.2e-5 over the 1538.46-sample window of dt = 1 ms)
    assert r['k_df'] == pytest.approx(s['k_df'], rel=3e-6 if whole else 3e-5)
    if whole:
        assert r['samples_per_cycle'] == pytest.approx(769, abs=1e-9)


def test_whole_cycle_dt():
    assert whole_cycle_dt(1.3, 1000.0) == pytest.approx(1 / (1.3 * 769), rel=1e-15)
    assert whole_cycle_dt(4.0, 1000.0) == pytest.approx(1e-3, rel=1e-15)
    assert whole_cycle_dt(800.0, 1000.0) == pytest.approx(1 / 800.0)    # at least one sample per cycle
    with pytest.raises(ValueError):
        whole_cycle_dt(0.0, 1000.0)


def test_harmonic_definition_is_the_first_harmonic_the_fits_use():
    """kdyn='harmonic' is K* = K_ev(jw) (Eq. 11) + first harmonic of the Berg loop (by quadrature), the
    catalogue's ModelSpec.first_harmonic that rubber_rig.fitting fits; Eq. 25-27 and 30 on top of it."""
    f, a = np.meshgrid([0.5, 1.3, 4, 14], [0.5e-3, 1e-3])
    for p in (P20, P40):
        h = steady_state_properties(p, f, a, kdyn='harmonic')
        k_ev = zener_complex_stiffness(2 * np.pi * f, p.k0, p.k_inf, p.tau, p.alpha)
        k_f = friction_first_harmonic(p.f_fmax, p.x2, a)
        k = k_ev + k_f
        np.testing.assert_allclose(spec_from_params(p).first_harmonic(f, a), k, rtol=1e-12)
        energy = np.pi * a ** 2 * k.imag
        expected = {'k_dyn': np.abs(k), 'loss_angle': np.angle(k), 'damping': energy / (np.pi * a ** 2 * np.abs(k)),
                    'energy': energy, 'c_eq': energy / (np.pi * 2 * np.pi * f * a ** 2),
                    'r_k': np.abs(k_ev - p.k0) / np.abs(k_f), 'r_e': k_ev.imag / k_f.imag}
        for key, value in expected.items():
            np.testing.assert_allclose(h[key], value, rtol=1e-12, err_msg=key)
        assert h['kdyn_definition'] == 'harmonic'


def test_eq24_and_harmonic_differ_by_the_measured_amount():
    """The Eq. 24 ellipse under-states the first-harmonic K_dyn, most at -40 degC and 1 mm: measured over
    0.5-14 Hz, 0.5 and 1 mm, the four temperatures: max 1.03 % at -40 degC, 0.5 Hz, 1 mm (0.99 % at 1.3 Hz;
    0.16 % at 20 degC). Energy, C_eq and R_E agree (only the first harmonic does work); R_K up to +4.3 %."""
    f = np.geomspace(0.5, 14, 200)[:, None]
    a = np.array([0.5e-3, 1e-3])
    worst = {}
    for name in ('swing_arm_joint_20C', 'swing_arm_joint_0C', 'swing_arm_joint_m20C', 'swing_arm_joint_m40C'):
        p = load_parameter_set(name)
        h, e = steady_state_properties(p, f, a, kdyn='harmonic'), steady_state_properties(p, f, a, kdyn='eq24')
        for k in ('energy', 'c_eq', 'r_e', 'energy_friction'):
            np.testing.assert_allclose(e[k], h[k], rtol=1e-12, err_msg=k)
        gap = e['k_dyn'] / h['k_dyn'] - 1
        assert np.all(gap < 0)
        i = np.unravel_index(np.argmin(gap), gap.shape)
        worst[name] = (-gap[i], f[i[0], 0], a[i[1]])
        assert np.all(e['r_k'] > h['r_k'])
    gap, f_w, a_w = worst['swing_arm_joint_m40C']
    assert 0.0102 < gap < 0.0104 and f_w == pytest.approx(0.5) and a_w == 1e-3
    assert max(g for g, _, _ in worst.values()) == gap
    assert 0.0015 < worst['swing_arm_joint_20C'][0] < 0.0017
    one = [steady_state_properties(P40, 1.3, 1e-3, kdyn=k)['k_dyn'] for k in ('eq24', 'harmonic')]
    assert 0.0098 < 1 - one[0] / one[1] < 0.0100


def test_harmonic_definition_of_a_memoryless_spring():
    """A cubic spring k1 x + k3 x^3: first harmonic k1 + 3/4 k3 x0^2, peak secant (eq24) k1 + k3 x0^2."""
    k1, k3, x0 = 1e6, 2e11, 1e-3
    m = ParallelModel([PolynomialSpring([0.0, k1, 0.0, k3]), LinearSpring(5e5)], dt=1e-3)
    h = steady_state_properties(m, 2.0, x0, kdyn='harmonic')
    e = steady_state_properties(m, 2.0, x0, kdyn='eq24')
    assert h['k_dyn'] == pytest.approx(k1 + 0.75 * k3 * x0 ** 2 + 5e5, rel=1e-12)
    assert e['k_dyn'] == pytest.approx(k1 + k3 * x0 ** 2 + 5e5, rel=1e-12)
    r = time_domain_properties(m, 2.0, x0, cycles=3)
    assert r['k_dyn'] == pytest.approx(h['k_dyn'], rel=1e-9)


def test_invalid_inputs():
    with pytest.raises(ValueError, match='kdyn'):
        steady_state_properties(P20, 1.0, 1e-3, kdyn='peak')
    for f, a in ((0.0, 1e-3), (1.0, -1e-3), (float('nan'), 1e-3)):
        with pytest.raises(ValueError):
            steady_state_properties(P20, f, a)
