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

"""The pieces of an identification a metrologist reads: the misfit test, the uncertainty budget, intervals
that respect physical bounds, structured warnings, and the noise estimate's own uncertainty."""
import copy
import math
import pickle

import numpy as np
import pytest

from rubber_rig.fitting.blocks import noise_level, noise_variance_uncertainty
from rubber_rig.fitting.budget import add_budget, interval, undeclared
from rubber_rig.fitting.fitwarnings import FitWarning, warning_dict, warning_text
from rubber_rig.fitting.misfit import MISFIT_P, misfit_test


def test_the_misfit_test_is_calibrated_on_chi2_draws_and_sees_a_5_percent_excess():
    # under the model: chi2 ~ chi2(dof) divided by a noise variance estimated with 1 % relative uncertainty;
    # the test must flag about MISFIT_P of such draws, not the 0 % a fixed 1.5 threshold would at this dof
    rng = np.random.default_rng(0)
    dof, u = 4900, 0.01
    draws = rng.chisquare(dof, 20000) / (1 + u * rng.standard_normal(20000))
    flagged = np.mean([misfit_test(c, dof, u)['misfit'] for c in draws])
    assert flagged < 5 * MISFIT_P
    # the model error: chi2/dof 1.10 over 4900 points passes a 1.5 threshold and fails the test
    assert misfit_test(1.10 * dof, dof, u)['misfit'] and misfit_test(1.10 * dof, dof, u)['z'] > 4
    # the same ratio over 40 table rows is chance
    assert not misfit_test(1.10 * 40, 40, 0.0)['misfit']
    assert misfit_test(2.0 * 40, 40, 0.0)['misfit']
    # a poorly known noise level makes the test humble: 1.10 with a 5 % uncertain noise variance is 2 sigma
    assert not misfit_test(1.10 * dof, dof, 0.05)['misfit']


def test_the_noise_estimate_carries_its_own_uncertainty():
    rng = np.random.default_rng(1)
    t = np.arange(50000) * 1e-3
    x = 1000 * np.sin(2 * np.pi * 2 * t) + rng.normal(0, 20, t.size)
    assert noise_level(x) == pytest.approx(20, rel=0.02)
    u = noise_variance_uncertainty(x)
    # the MAD of third differences: about 1.36/n relative variance of sigma per independent sample, so a
    # variance uncertainty of a few per mille to a per cent at 50k samples
    assert 0.002 < u < 0.02
    # and it is honest: the spread of the estimate over independent records matches it
    est = [noise_level(1000 * np.sin(2 * np.pi * 2 * t) + rng.normal(0, 20, t.size)) ** 2 for _ in range(30)]
    assert np.std(est) / np.mean(est) == pytest.approx(u, rel=0.6)
    assert noise_variance_uncertainty(x[:500]) == math.inf       # too short to say


def test_intervals_respect_physical_bounds():
    lo, hi = interval(1.0, 0.6, 1.96, 'log')                         # a positive parameter, 60 % uncertain
    assert lo > 0 and hi > 1 + 0.6 * 1.96 and math.isclose(lo * hi, 1.0)
    lo, hi = interval(0.95, 0.1, 1.96, 'logit')                       # a fractional order near 1
    assert 0 < lo < 0.95 < hi < 1
    assert interval(-2.0, 1.0, 2.0, 'linear') == [-4.0, 0.0]        # a signed term keeps its symmetric interval
    assert interval(1.0, 2.2, 2.26, 'clipped') == [0.0, 1.0]         # an order at its bound 1, badly determined
    # a side the data do not bound is reported as unbounded (inf; 0 the physical bound), never an overflow
    assert interval(1e-300, 1.0, 2.0, 'log') == [0.0, math.inf]
    assert interval(2e5, 1e6, 2.0, 'log') == [0.0, math.inf]
    assert interval(1.0, math.nan, 2.0, 'linear') == [-math.inf, math.inf]


def test_the_budget_adds_declared_calibrations_by_root_sum_of_squares():
    def unc():
        return {'k0': {'value': 1e7, 'sigma': 1e4, 'interval_95': [1e7 - 2e4, 1e7 + 2e4]},
                'tau': {'value': 0.04, 'sigma': 0.001, 'interval_95': [0.038, 0.042]},
                'alpha': {'value': 0.6, 'sigma': 0.01, 'interval_95': [0.58, 0.62]}}
    kinds = {'k0': 'log', 'tau': 'log', 'alpha': 'order'}
    scales = {'k0': 'stiffness', 'tau': 'time', 'alpha': 'order'}
    shift = {'k0': 2e9, 'tau': -5.0, 'alpha': 100.0}      # per second of load-cell delay
    u = unc()
    add_budget(u, kinds, scales, {'gain': 1.0, 'gain_u': 0.003, 'delay_u': 20e-6}, delay_shift=shift)
    k0 = u['k0']
    assert k0['budget'] == pytest.approx({'type_a': 1e4, 'load_cell_gain': 3e4, 'load_cell_delay': 4e4})
    assert k0['sigma'] == pytest.approx(math.sqrt(1e8 + 9e8 + 16e8))
    assert k0['coverage_factor'] == pytest.approx(2.0) and k0['interval_method'] == 'log'
    assert k0['interval_95'][0] == pytest.approx(1e7 * math.exp(-2 * k0['sigma'] / 1e7))
    assert 'load_cell_gain' not in u['tau']['budget']                      # a time is not force-scaled
    assert u['tau']['budget']['load_cell_delay'] == pytest.approx(1e-4)
    assert undeclared(u) == []
    # nothing declared: the contributions are None (not zero), and listed as missing
    u = unc()
    add_budget(u, kinds, scales, {'gain': 1.0, 'gain_u': None, 'delay_u': None}, delay_shift=shift)
    assert u['k0']['budget']['load_cell_gain'] is None and u['k0']['sigma'] == 1e4
    assert undeclared(u) == ['load_cell_gain', 'load_cell_delay']
    # an estimated delay is a fit parameter: its uncertainty is Type A, not a separate term
    u = unc()
    add_budget(u, kinds, scales, {'gain': 1.0, 'gain_u': 0.0, 'delay_u': None}, delay_shift=shift,
               delay_estimated=True)
    assert 'load_cell_delay' not in u['k0']['budget']


def test_warnings_are_sentences_with_a_code_that_survive_copy_and_pickle():
    w = FitWarning('bounds', 'k0 ended at the edge of its search range', ('k0',))
    assert w == 'k0 ended at the edge of its search range' and w.startswith('k0 ended')
    for again in (copy.copy(w), copy.deepcopy(w), pickle.loads(pickle.dumps(w))):
        assert again.code == 'bounds' and again.parameters == ['k0'] and again == w
    assert warning_dict(w) == {'code': 'bounds', 'message': str(w), 'parameters': ['k0']}
    assert warning_dict('an old model file\'s warning')['code'] is None
    assert warning_text({'code': 'misfit', 'message': 'misfit beyond noise'}) == 'misfit beyond noise'
    with pytest.raises(ValueError, match='unknown warning code'):
        FitWarning('looks_bad', 'no such code')


def test_repeated_branches_have_a_canonical_order_by_relaxation_time():
    from rubber_rig.models.modelfile import parse_model
    spec = parse_model({'elements': [{'type': 'linear_spring', 'k': '1 kN/mm'},
                                     {'type': 'maxwell', 'k': '0.5 kN/mm', 'c': '2 kNs/m'},      # tau 4 ms
                                     {'type': 'maxwell', 'k': '0.3 kN/mm', 'c': '0.1 kNs/m'}]}, 'x')  # 0.33 ms
    rename = spec.canonical_names()
    assert rename == {'linear_spring.k': 'linear_spring.k', 'maxwell_1.k': 'maxwell_2.k',
                      'maxwell_1.c': 'maxwell_2.c', 'maxwell_2.k': 'maxwell_1.k', 'maxwell_2.c': 'maxwell_1.c'}
    ordered = spec.with_values({rename[n]: v for n, v in spec.values().items()})
    assert ordered.canonical_names() == {n: n for n in rename}                    # already canonical
    v = ordered.values()
    assert v['maxwell_1.c'] / v['maxwell_1.k'] < v['maxwell_2.c'] / v['maxwell_2.k']
    assert ordered.first_harmonic(5.0, 1e-3) == pytest.approx(spec.first_harmonic(5.0, 1e-3), rel=1e-12)


def test_the_fractional_order_range_of_the_time_domain_scheme_is_stated_and_checked():
    from rubber_rig.models.elements import FractionalZener
    from rubber_rig.models.fractional import zener_complex_stiffness
    from rubber_rig.models.modelfile import parse_model
    f = np.array([0.05, 0.5, 5.0, 50.0])
    for alpha in (0.1, 0.3, 0.66, 0.99):            # inside the range: the stated bound holds
        z = FractionalZener(12.29e6, 14.01e6, 0.043, alpha, 1e-3)
        k = z.discrete_complex_stiffness(f)
        exact = zener_complex_stiffness(2 * np.pi * f, 12.29e6, 14.01e6, 0.043, alpha)
        assert np.max(np.abs(k.real / exact.real - 1)) < 0.0015 and np.max(np.abs(k.imag / exact.imag - 1)) < 0.009
    with pytest.raises(ValueError, match='alpha 0.05 outside 0.1..1'):
        FractionalZener(12.29e6, 14.01e6, 0.043, 0.05, 1e-3)
    with pytest.raises(ValueError, match='alpha'):
        parse_model({'elements': [{'type': 'fractional_zener', 'k0': '12 kN/mm', 'k_inf': '14 kN/mm',
                                   'tau': '43 ms', 'alpha': 0.01}]}, 'small_order.yaml')


def test_the_power_of_length_in_each_catalogue_unit():
    from rubber_rig.fitting.budget import length_exponent
    assert [length_exponent(u) for u in ('N/m', 'N/m^3', 'm', 'N s^alpha/m', 's/m', 's', '-', 'N', 'N/m^5')] == [
        -1, -3, 1, -1, -1, 0, 0, 0, -5]
