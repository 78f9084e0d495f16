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

"""Parameter sets, validation and temperature interpolation (seed 000 Table 1/2)."""
import dataclasses

import numpy as np
import pytest

from rubber_rig.models import (
    KelvinVoigtParams,
    ZenerBergParams,
    build_model,
    list_parameter_sets,
    load_parameter_set,
    parameters_at_temperature,
)

TABLE1 = {  # paper units: kN/mm, kN/mm, s, -, mm, kN
    'seed000_20C': (20, 12.29, 14.01, 0.043, 0.659, 1.41, 4.57),
    'seed000_0C': (0, 12.31, 14.08, 0.031, 0.796, 1.58, 7.77),
    'seed000_m20C': (-20, 12.82, 17.98, 0.018, 0.864, 1.09, 6.18),
    'seed000_m40C': (-40, 15.06, 27.09, 0.015, 0.861, 0.463, 6.86),
}


def _si(row):
    _, k0, ki, tau, a, x2, ff = row
    return ZenerBergParams(k0 * 1e6, ki * 1e6, tau, a, x2 * 1e-3, ff * 1e3)


def test_table1_loaded_in_si():
    for name, row in TABLE1.items():
        p = load_parameter_set(name)
        assert isinstance(p, ZenerBergParams)
        np.testing.assert_allclose(list(p.as_dict().values()), list(_si(row).as_dict().values()), rtol=1e-12)


def test_table2_cases():
    names = list_parameter_sets()
    for i in range(1, 10):
        assert f'swing_arm_joint_case{i}' in names and f'seed000_case{i}' not in names   # aliases are not listed
    kv = load_parameter_set('seed000_case1')
    assert isinstance(kv, KelvinVoigtParams) and kv.k == 14e6 and kv.c == 243e3
    assert load_parameter_set('seed000_case2') == load_parameter_set('seed000_20C')
    assert load_parameter_set('seed000_case9') == load_parameter_set('seed000_m40C')
    c4 = load_parameter_set('seed000_case4')
    assert (c4.k0, c4.k_inf) == (5.5e6, 20e6)
    c6 = load_parameter_set('seed000_case6')
    assert (c6.x2, c6.f_fmax) == (0.705e-3, 8000.0)


def test_unknown_set_named_in_error():
    with pytest.raises(ValueError, match='seed000_99C'):
        load_parameter_set('seed000_99C')


def test_names_and_dict():
    assert ZenerBergParams.names() == ('k0', 'k_inf', 'tau', 'alpha', 'x2', 'f_fmax')
    p = load_parameter_set('seed000_20C')
    assert ZenerBergParams(**p.as_dict()) == p
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.k0 = 1.0


BAD = [('alpha', 0.0), ('alpha', 1.2), ('alpha', -0.5), ('k0', 0.0), ('k0', -1e6), ('tau', 0.0),
       ('tau', -1.0), ('x2', 0.0), ('x2', -1e-3), ('f_fmax', 0.0), ('f_fmax', -5.0),
       ('k0', float('nan')), ('tau', float('inf')), ('alpha', float('nan')), ('k_inf', float('inf')),
       ('x2', float('nan')), ('tau', 'abc')]


@pytest.mark.parametrize('field,value', BAD)
def test_bad_parameters_rejected_naming_the_field(field, value):
    d = load_parameter_set('seed000_20C').as_dict()
    d[field] = value
    if not isinstance(value, str):
        with pytest.raises(ValueError, match=field):
            ZenerBergParams(**d).validate()
    with pytest.raises(ValueError, match=field):
        build_model({'model': 'seed000', 'values': d}, dt=1e-3)


def test_k_inf_below_k0_rejected():
    d = load_parameter_set('seed000_20C').as_dict()
    d['k_inf'] = d['k0'] * 0.9
    with pytest.raises(ValueError, match='k_inf'):
        ZenerBergParams(**d).validate()


def test_alpha_one_is_valid():
    d = load_parameter_set('seed000_20C').as_dict()
    d['alpha'] = 1.0
    ZenerBergParams(**d).validate()


def test_temperature_exact_at_table_points():
    for name, row in TABLE1.items():
        p = parameters_at_temperature(row[0])
        np.testing.assert_allclose(list(p.as_dict().values()), list(load_parameter_set(name).as_dict().values()),
                                   rtol=1e-12)


def test_temperature_interpolation_monotone_smooth_and_valid():
    temps = np.array([-40.0, -20.0, 0.0, 20.0])
    nodes = [parameters_at_temperature(t).as_dict() for t in temps]
    grid = [np.linspace(temps[i], temps[i + 1], 201) for i in range(3)]
    for field in ZenerBergParams.names():
        for i, tg in enumerate(grid):
            vals = np.array([getattr(parameters_at_temperature(t), field) for t in tg])
            lo, hi = sorted((nodes[i][field], nodes[i + 1][field]))
            # PCHIP: no overshoot between table points, monotone in the direction of the table
            assert vals.min() >= lo * (1 - 1e-12) and vals.max() <= hi * (1 + 1e-12), field
            d = np.diff(vals) * np.sign(nodes[i + 1][field] - nodes[i][field])
            assert np.all(d >= -1e-9 * abs(hi)), (field, i)
    # C1: one-sided slopes agree across the interior table temperatures (10 mK steps)
    for t in (-20.0, 0.0):
        for field in ('k0', 'k_inf', 'tau', 'alpha'):
            def f(tt, field=field):
                return getattr(parameters_at_temperature(tt), field)
            left, right = (f(t) - f(t - 0.01)) / 0.01, (f(t + 0.01) - f(t)) / 0.01
            scale = abs(f(t + 10) - f(t - 10)) / 20 + 1e-300
            assert abs(left - right) <= 0.02 * scale + 1e-12 * abs(f(t)), (field, t)
    for t in np.linspace(-40, 20, 61):
        p = parameters_at_temperature(t)
        assert p.k_inf > p.k0 and 0 < p.alpha <= 1


@pytest.mark.parametrize('t', [-40.1, 20.5, float('nan')])
def test_temperature_outside_table_rejected(t):
    with pytest.raises(ValueError, match='temperature'):
        parameters_at_temperature(t)


def test_build_model_specs_agree():
    p = load_parameter_set('seed000_m20C')
    x = 1e-3 * np.sin(2 * np.pi * 3 * np.arange(500) * 1e-3)
    ref = build_model(p, 1e-3).run(x)
    for spec in ({'model': 'seed000', 'parameter_set': 'seed000_m20C'}, {'model': 'seed000', 'temperature': -20},
                 {'model': 'seed000', 'values': p.as_dict()}, 'seed000_m20C'):
        m = build_model(spec, 1e-3)
        assert m.branch_names == ('elastic', 'viscous', 'friction')
        np.testing.assert_allclose(m.run(x), ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


@pytest.mark.parametrize('spec,match', [({'model': 'seed000'}, 'exactly one'),
                                        ({'model': 'nope', 'values': {}}, 'nope'),
                                        ({'model': 'seed000', 'values': {'k0': 1}}, 'missing'),
                                        ({'model': 'parallel', 'elements': [{'type': 'warp'}]}, 'warp')])
def test_bad_specs(spec, match):
    with pytest.raises(ValueError, match=match):
        build_model(spec, 1e-3)


def test_bad_dt():
    for dt in (0, -1e-3, float('nan')):
        with pytest.raises(ValueError, match='dt'):
            build_model('seed000_20C', dt)


def test_core_never_imports_rclpy():
    import subprocess
    import sys
    code = ('import sys, rubber_rig.models, rubber_rig.analysis, rubber_rig.cli.props, rubber_rig.units; '
            'bad = [m for m in sys.modules if m.split(".")[0] in ("rclpy", "rosidl_runtime_py")]; '
            'sys.exit(1 if bad else 0)')
    assert subprocess.run([sys.executable, '-c', code]).returncode == 0


def test_parameter_set_from_a_fitted_yaml_file(tmp_path):
    """A file in the shipped layout (what `rubber-rig fit` writes) loads by path, as FILE or FILE:SET."""
    one = tmp_path / 'one.yaml'
    one.write_text('sets:\n  fit_m10C: {model: seed000, values: {k0: 12.5e6, k_inf: 15.0e6, tau: 0.03, '
                   'alpha: 0.8, x2: 1.2e-3, f_fmax: 6000.0}}\n')
    p = load_parameter_set(str(one))
    assert (p.k0, p.k_inf, p.tau, p.alpha, p.x2, p.f_fmax) == (12.5e6, 15.0e6, 0.03, 0.8, 1.2e-3, 6000.0)
    assert load_parameter_set(f'{one}:fit_m10C') == p

    two = tmp_path / 'two.yaml'
    two.write_text(one.read_text() + '  fit_20C: {model: seed000, values: {k0: 12.3e6, k_inf: 14.0e6, '
                   'tau: 0.043, alpha: 0.66, x2: 1.4e-3, f_fmax: 4600.0}}\n')
    assert load_parameter_set(f'{two}:fit_20C').tau == 0.043
    with pytest.raises(ValueError, match='holds 2 parameter sets.*fit_20C, fit_m10C'):
        load_parameter_set(str(two))
    with pytest.raises(ValueError, match="unknown parameter set 'nope'"):
        load_parameter_set(f'{two}:nope')
    with pytest.raises(FileNotFoundError, match='no such parameter file'):
        load_parameter_set(str(tmp_path / 'missing.yaml'))
    bad = tmp_path / 'bad.yaml'
    bad.write_text('sets:\n  s: {model: seed000, values: {k0: 12.5e6, k_inf: 11.0e6, tau: 0.03, '
                   'alpha: 0.8, x2: 1.2e-3, f_fmax: 6000.0}}\n')
    with pytest.raises(ValueError, match='k_inf'):
        load_parameter_set(str(bad))


@pytest.mark.parametrize('content, why', [
    (b'\x89PNG\r\n\x1a\n\x00\xff\xfe', 'not a YAML text file (byte 0x89 at offset 0 is not UTF-8'),
    (b'sets: [unclosed\n  a: {b\n', 'not valid YAML (line 2, column 4: '),
])
def test_a_binary_or_broken_parameter_file_is_a_one_line_value_error(tmp_path, content, why):
    """A binary file was a bare UnicodeDecodeError, broken YAML a message over several lines with a caret drawing."""
    path = tmp_path / 'set.yaml'
    path.write_bytes(content)
    with pytest.raises(ValueError) as err:
        load_parameter_set(f'{path}:s')
    assert str(err.value).startswith(f'{path}: {why}') and '\n' not in str(err.value), str(err.value)
    assert not isinstance(err.value, UnicodeDecodeError)


def test_physics_names_and_the_earlier_names_give_the_same_sets():
    """Sets and model types have physics names; the earlier seed-file names still load (recordings carry them)."""
    from rubber_rig.models import (
        TangentMaxwellBergParams,
        build_model,
        canonical_model,
        model_class,
    )
    for tag in ('20C', '0C', 'm20C', 'm40C', 'case1', 'case5'):
        assert load_parameter_set(f'seed000_{tag}') == load_parameter_set(f'swing_arm_joint_{tag}')
    assert canonical_model('seed000') == 'fractional_zener_berg' and model_class('seed001') is TangentMaxwellBergParams
    with pytest.raises(ValueError, match='unknown model .nope.*fractional_zener_berg'):
        model_class('nope')
    old = build_model({'model': 'seed000', 'parameter_set': 'seed000_20C'}, 1e-3)
    new = build_model({'model': 'fractional_zener_berg', 'parameter_set': 'swing_arm_joint_20C'}, 1e-3)
    x = 1e-3 * np.sin(2 * np.pi * 4.0 * np.arange(500) * 1e-3)
    np.testing.assert_array_equal(old.run(x), new.run(x))
    assert new.name == 'fractional_zener_berg'


def test_each_set_stores_its_temperature_and_source():
    """The temperature of a set comes from its data file, not from its name."""
    from rubber_rig.models import parameter_set_info
    for name, row in TABLE1.items():
        info = parameter_set_info(name)
        assert info['temperature'] == row[0] and info['source'] == 'seed 000 Table 1'
        assert info['model'] == 'fractional_zener_berg'
    assert parameter_set_info('seed000_case9')['temperature'] == -40.0
    assert np.isnan(parameter_set_info('swing_arm_joint_case4')['temperature'])   # a hypothetical variant
    assert parameter_set_info('seed000_case4')['source'] == 'seed 000 Table 2 case 4'
