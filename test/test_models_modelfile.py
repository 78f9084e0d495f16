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

"""Model files and the element catalogue: units, errors that name the entry, exact first harmonics."""
import numpy as np
import pytest

from rubber_rig.models import build_model, load_parameter_set
from rubber_rig.models.catalogue import TYPES, catalogue, element_type
from rubber_rig.models.modelfile import (
    NAMED_MODELS,
    load_model_file,
    named_model,
    parse_model,
    resolve_model,
    spec_from_params,
)

CUBIC = """
name: bushing
temperature: 20 degC
elements:
  - {type: fractional_zener, k0: 12.29 kN/mm, k_inf: 14.01 kN/mm, tau: 0.043 s, alpha: 0.659}
  - {type: berg, x2: 1.41 mm, f_fmax: 4.57 kN, fixed: [x2]}
  - {type: polynomial_spring, k3: 6e11 N/m^3}
"""


def test_a_model_file_reads_values_with_units_into_si(tmp_path):
    path = tmp_path / 'bushing.yaml'
    path.write_text(CUBIC)
    spec = load_model_file(path)
    assert spec.name == 'bushing' and spec.meta['temperature'] == 20.0
    assert spec.values() == pytest.approx({'k0': 12.29e6, 'k_inf': 14.01e6, 'tau': 0.043, 'alpha': 0.659,
                                           'x2': 1.41e-3, 'f_fmax': 4570.0, 'k3': 6e11})
    assert [n for n, _, _ in spec.free()] == ['k0', 'k_inf', 'tau', 'alpha', 'f_fmax', 'k3']
    # a path, {'model_file': path} and the spec build the same model
    x = 1e-3 * np.sin(2 * np.pi * 3.0 * np.arange(2000) * 1e-3)
    ref = build_model(spec, 1e-3).run(x)
    for source in (str(path), {'model_file': str(path)}):
        np.testing.assert_array_equal(build_model(source, 1e-3).run(x), ref)


def test_the_written_file_reads_back_and_ignores_the_uncertainties(tmp_path):
    spec = parse_model(__import__('yaml').safe_load(CUBIC))
    results = {n: {'sigma': 0.01 * v, 'interval_95': [0.98 * v, 1.02 * v]} for n, v in spec.values().items()}
    back = load_model_file(spec.dump(tmp_path / 'fit.yaml', results=results))
    assert back.values() == pytest.approx(spec.values(), rel=1e-15)
    assert back.elements[1].fixed == frozenset({'x2'})
    text = (tmp_path / 'fit.yaml').read_text()
    assert 'sigma' in text and 'interval_95' in text


@pytest.mark.parametrize('elements, match', [
    ([{'type': 'warp'}], "unknown element type 'warp'"),
    ([{'type': 'berg', 'x2': '1 mm'}], 'berg needs f_fmax'),
    ([{'type': 'berg', 'x2': '1 mm', 'f_fmax': '4 kN', 'mu': 3}], "unknown parameter 'mu' of berg"),
    ([{'type': 'berg', 'x2': '1 kN', 'f_fmax': '4 kN'}], r"elements\[0\].x2: '1 kN' is a force, expected a length"),
    ([{'type': 'berg', 'x2': '-1 mm', 'f_fmax': '4 kN'}], 'x2 must be > 0'),
    ([{'type': 'fractional_zener', 'k0': '14 kN/mm', 'k_inf': '12 kN/mm', 'tau': 0.04, 'alpha': 0.6}],
     'k_inf .* must be >= k0'),
    ([{'type': 'fractional_zener', 'k0': 1e7, 'k_inf': 2e7, 'tau': 0.04, 'alpha': 1.5}], 'alpha must be <= 1'),
    ([{'type': 'polynomial_spring'}], 'needs at least one of'),
    ([{'type': 'berg', 'x2': '1 mm', 'f_fmax': '4 kN', 'fixed': ['k0']}], 'k0 is not a parameter'),
    ([], 'needs "elements"'),
])
def test_bad_model_files_say_what_is_wrong(elements, match):
    with pytest.raises(ValueError, match=match):
        parse_model({'elements': elements}, 'bad.yaml')


def test_missing_model_file_is_a_file_not_found_error(tmp_path):
    with pytest.raises(FileNotFoundError, match='nope.yaml'):
        resolve_model(str(tmp_path / 'nope.yaml'))


def test_named_models_and_parameter_sets_resolve_and_build():
    for name in NAMED_MODELS:
        spec = named_model(name)
        model = build_model(spec, 1e-3)
        x = 0.3e-3 * np.sin(2 * np.pi * 2.0 * np.arange(1500) * 1e-3) - (1e-3 if name == 'pad' else 0.0)
        assert np.all(np.isfinite(model.run(x)))
    spec = named_model('swing_arm_joint_m40C')
    assert spec.meta['temperature'] == -40.0
    assert [e.type for e in spec.elements] == ['fractional_zener', 'berg']
    with pytest.raises(ValueError, match='unknown model'):
        named_model('no_such_model')


def test_a_parameter_set_as_a_model_file_runs_the_same_model():
    p = load_parameter_set('swing_arm_joint_0C')
    x = 1e-3 * np.sin(2 * np.pi * 4.0 * np.arange(3000) * 1e-3)
    np.testing.assert_array_equal(build_model(spec_from_params(p), 1e-3).run(x), build_model(p, 1e-3).run(x))


def test_the_catalogue_names_units_and_sources_of_every_type():
    entries = {e['type']: e for e in catalogue()}
    for required in ('fractional_zener', 'berg', 'polynomial_spring', 'two_order_fractional', 'elliptic_damping',
                     'maxwell', 'dashpot', 'tanh_coulomb', 'dzierzek', 'operating_point_spring'):
        assert required in entries
        assert entries[required]['source'].startswith('seed 00')
    assert {p['name']: p['unit'] for p in entries['fractional_zener']['parameters']} == {
        'k0': 'N/m', 'k_inf': 'N/m', 'tau': 's', 'alpha': '-'}
    assert element_type('smooth_coulomb') is TYPES['tanh_coulomb']


def _measured_first_harmonic(element_spec, f, a, mean, fs=20000.0, cycles=6):
    """First harmonic F1 / X1 [N/m] of the last 2 of ``cycles`` steady cycles of the element run on a sine."""
    spec = parse_model({'elements': [element_spec]})
    model = build_model(spec, 1.0 / fs)
    n_per = int(round(fs / f))
    t = np.arange(cycles * n_per) / fs
    x = mean + a * np.sin(2 * np.pi * f * t)
    model.reset(x[0])
    force = model.run(x)
    last = slice((cycles - 2) * n_per, cycles * n_per)
    e = np.exp(-2j * np.pi * f * t[last])
    return (force[last] @ e) / ((x[last] - mean) @ e), spec


@pytest.mark.parametrize('element, mean', [
    ({'type': 'fractional_zener', 'k0': 1.2e7, 'k_inf': 1.4e7, 'tau': 0.043, 'alpha': 0.66}, 0.0),
    ({'type': 'zener', 'k0': 1.2e7, 'k_inf': 1.4e7, 'tau': 0.043}, 0.0),
    ({'type': 'berg', 'x2': 1.4e-3, 'f_fmax': 4570.0}, 0.0),
    ({'type': 'polynomial_spring', 'k1': 2e6, 'k2': 3e8, 'k3': 6e11, 'k5': 1e17}, -1.1e-3),
    ({'type': 'dzierzek', 'k_t': 2e6, 'd_t': 6e-3}, 0.5e-3),
    ({'type': 'two_order_fractional', 'k1': 6e6, 'k2': 3e6, 'c1': 6e5, 'c2': 1.5e5, 'alpha': 0.3, 'beta': 0.6}, 0.0),
    ({'type': 'elliptic_damping', 'b': 340.0}, -1.1e-3),
    ({'type': 'maxwell', 'k': 2e6, 'c': 1e4}, 0.0),
    ({'type': 'dashpot', 'c': 2e4}, 0.0),
    ({'type': 'tanh_coulomb', 'f_c': 300.0, 'a': 20.0}, 0.0),
])
def test_the_first_harmonic_of_every_type_is_what_the_element_does_on_a_sine(element, mean):
    """The catalogue's first harmonic (used by the fits) against the element's own time-domain response at
    20 kHz: 0.5 % of |K| (the remaining difference is the discrete velocity and the sum-of-exponentials scheme)."""
    for f, a in ((1.0, 1e-3), (10.0, 0.4e-3)):
        measured, spec = _measured_first_harmonic(element, f, a, mean)
        exact = spec.first_harmonic(f, a, mean)
        assert abs(exact - measured) < 5e-3 * abs(exact), (element['type'], f, a, exact, measured)


def test_the_simulated_rig_takes_a_model_file_as_its_specimen(tmp_path):
    from rubber_rig.rig.config import ConfigError
    from rubber_rig.rig.sim.specimen import build_specimen
    path = tmp_path / 'bushing.yaml'
    path.write_text(CUBIC)
    x = 1e-3 * np.sin(2 * np.pi * 3.0 * np.arange(1000) * 1e-3)
    np.testing.assert_array_equal(build_specimen({'model_file': str(path)}, 1e-3).run(x),
                                  build_model(str(path), 1e-3).run(x))
    # as the rig driver's sim.specimen.parameter_set passes it (with model and deadband), like element_model's
    driver = {'model': 'fractional_zener_berg', 'parameter_set': str(path), 'friction_reversal_threshold': 2e-6}
    np.testing.assert_array_equal(build_specimen(driver, 1e-3).run(x),
                                  build_model(str(path), 1e-3, friction_reversal_threshold=2e-6).run(x))
    (tmp_path / 'bad.yaml').write_text('elements: [{type: berg, x2: 1 kN, f_fmax: 4 kN}]\n')
    with pytest.raises(ConfigError, match='sim.specimen.*bad.yaml.*x2'):
        build_specimen({'model_file': str(tmp_path / 'bad.yaml')}, 1e-3)


@pytest.mark.parametrize('threshold, scheme', [(0.0, 'default'), (2e-6, 'default'), (0.0, 'paper')])
def test_the_default_specimen_built_from_its_model_spec_gives_the_forces_of_its_elements(tmp_path, threshold, scheme):
    """Every model is built through its ModelSpec (catalogue); the simulated rig's default specimen (seed 000 at
    20 degC) must still give the forces of fractional Zener + Berg built element by element, as before (1e-9
    relative), and so must the same model written as a model file, on the simulated rig and in build_model.
    """
    from rubber_rig.models import ParallelModel, parameters_at_temperature
    from rubber_rig.models.catalogue import fractional_element
    from rubber_rig.models.friction import BergFriction
    from rubber_rig.rig.sim.specimen import build_specimen
    p, dt = parameters_at_temperature(20.0), 1e-3 if scheme == 'paper' else 2e-4
    t = np.arange(int(4.0 / dt)) * dt
    x = 1e-3 * np.sin(2 * np.pi * 3.0 * t) + 2e-4 * np.sin(2 * np.pi * 11.0 * t)
    direct = ParallelModel([fractional_element(p.k0, p.k_inf, p.tau, p.alpha, dt, scheme),
                            BergFriction(p.f_fmax, p.x2, dt, threshold)], dt).run(x)
    spec = {'model': 'fractional_zener_berg', 'temperature': 20.0, 'friction_reversal_threshold': threshold,
            'scheme': scheme}
    model = build_model(spec, dt)
    assert model.name == 'fractional_zener_berg' and model.params == p
    assert model.branch_names == ('elastic', 'viscous', 'friction')
    scale = np.max(np.abs(direct))
    for built in (build_specimen(spec, dt).run(x), model.run(x)):
        np.testing.assert_allclose(built, direct, rtol=0, atol=1e-9 * scale)
    path = spec_from_params(p).dump(tmp_path / 'seed000_20C.yaml')
    from_file = {'model_file': str(path), 'friction_reversal_threshold': threshold, 'scheme': scheme}
    for built in (build_specimen(from_file, dt).run(x), build_model(from_file, dt).run(x)):
        np.testing.assert_allclose(built, direct, rtol=0, atol=1e-9 * scale)
