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

"""`rubber-rig props` and unit-suffix parsing."""
import json

import numpy as np
import pytest

from rubber_rig.cli.main import main
from rubber_rig.models import (
    build_model,
    load_parameter_set,
    parameters_at_temperature,
    steady_state_properties,
    time_domain_properties,
)
from rubber_rig.units import to_si


@pytest.mark.parametrize('text,dim,value', [
    ('1mm', 'length', 1e-3), ('0.5 mm', 'length', 5e-4), ('4.57kN', 'force', 4570.0), ('10Hz', 'frequency', 10.0),
    ('1kHz', 'frequency', 1000.0), ('14kN/mm', 'stiffness', 14e6), ('243kN*s/m', 'damping', 243e3),
    ('2.5', 'length', 2.5), ('-10degC', 'temperature', -10.0), ('263.15K', 'temperature', -10.0),
    ('1e-3m', 'length', 1e-3), ('250us', 'time', 250e-6), ('2 cm', 'length', 0.02), ('5 mm/s', 'velocity', 5e-3),
    (3, 'number', 3.0), (0.5e-3, 'length', 5e-4)])
def test_to_si(text, dim, value):
    assert to_si(text, dim) == pytest.approx(value, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize('text,dim,match', [('1kN', 'length', 'force'), ('1 parsec', 'length', 'unit'),
                                            ('abc', 'length', 'number'), ('inf', 'length', 'number'),
                                            (float('nan'), 'length', 'finite'), ('1e400 mm', 'length', 'finite'),
                                            (True, 'length', 'expected a length'), ('3 Hz', 'number', 'bare number')])
def test_to_si_errors(text, dim, match):
    with pytest.raises(ValueError, match=match):
        to_si(text, dim)


def run_json(capsys, *argv):
    assert main(['props', *argv, '--json']) == 0
    return json.loads(capsys.readouterr().out)


def test_json_analytic_matches_library(capsys):
    rows = run_json(capsys, '-p', 'seed000_20C', '-f', '0.5Hz', '4', '-a', '0.5mm', '1e-3')
    assert len(rows) == 4
    p = load_parameter_set('seed000_20C')
    for r in rows:
        assert set(r) == {'frequency', 'amplitude', 'k_dyn', 'loss_angle', 'damping', 'c_eq', 'energy', 'r_k', 'r_e',
                          'kdyn_definition'}
        assert r.pop('kdyn_definition') == 'harmonic'      # the CLI default: the exact first harmonic
        s = steady_state_properties(p, r['frequency'], r['amplitude'], kdyn='harmonic')
        for k in r:
            assert r[k] == pytest.approx(s[k], rel=1e-12)
    assert {(r['frequency'], r['amplitude']) for r in rows} == {(0.5, 5e-4), (4.0, 5e-4), (0.5, 1e-3), (4.0, 1e-3)}


def test_temperature_and_grid(capsys):
    rows = run_json(capsys, '--temperature=-10degC', '--frequency-grid', '0.5Hz', '14Hz', '5', '-a', '1mm')
    assert len(rows) == 5
    np.testing.assert_allclose([r['frequency'] for r in rows], np.geomspace(0.5, 14, 5))
    s = steady_state_properties(parameters_at_temperature(-10), 14.0, 1e-3, kdyn='harmonic')
    assert rows[-1]['k_dyn'] == pytest.approx(s['k_dyn'], rel=1e-9)


def test_time_method_agrees_with_analytic(capsys):
    a = run_json(capsys, '-p', 'seed000_m20C', '-f', '4Hz', '-a', '1mm')[0]
    t = run_json(capsys, '-p', 'seed000_m20C', '-f', '4Hz', '-a', '1mm', '--method', 'time')[0]
    assert t['kdyn_definition'] == a['kdyn_definition'] == 'harmonic'
    assert t['k_dyn'] == pytest.approx(a['k_dyn'], rel=1e-3)
    assert t['energy'] == pytest.approx(a['energy'], rel=5e-3)
    assert t['r_k'] == pytest.approx(a['r_k'], rel=5e-3)
    assert t['r_e'] == pytest.approx(a['r_e'], rel=1e-2)


def test_time_method_at_the_reported_point(capsys):
    """The issue's case: -40 degC, 1.3 Hz (769.23 samples per cycle at 1 kHz), 1 mm. The time method gave
    K_dyn +0.87 % (2 cycles rounded down to one, drift column in the fit); now each frequency runs at a
    whole number of samples per cycle (769) and two whole cycles are analysed. Measured -0.0063 % against
    the analytic first harmonic (the fractional scheme's discretisation); tolerance 0.02 %."""
    argv = ('-p', 'swing_arm_joint_m40C', '-f', '1.3Hz', '-a', '1mm')
    a = run_json(capsys, *argv)[0]
    t = run_json(capsys, *argv, '--method', 'time')[0]
    assert t['k_dyn'] == pytest.approx(a['k_dyn'], rel=2e-4)
    assert t['loss_angle'] == pytest.approx(a['loss_angle'], abs=1e-3)
    assert t['r_k'] == pytest.approx(a['r_k'], rel=5e-3)
    # the Python API at exactly 1 kHz (a window of 1538 samples for 1538.46) agrees as well
    m = build_model('swing_arm_joint_m40C', 1e-3)
    assert time_domain_properties(m, 1.3, 1e-3)['k_dyn'] == pytest.approx(a['k_dyn'], rel=2e-4)


def test_kdyn_option_selects_and_names_the_definition(capsys):
    argv = ('-p', 'swing_arm_joint_m40C', '-f', '0.5', '1.3', '-a', '1mm')
    h = run_json(capsys, *argv, '--kdyn', 'harmonic')
    e = run_json(capsys, *argv, '--kdyn', 'eq24')
    assert [r['kdyn_definition'] for r in h + e] == ['harmonic'] * 2 + ['eq24'] * 2
    assert h == run_json(capsys, *argv)                   # harmonic is the default
    p = load_parameter_set('swing_arm_joint_m40C')
    for rows, kdyn in ((h, 'harmonic'), (e, 'eq24')):
        for r in rows:
            s = steady_state_properties(p, r['frequency'], r['amplitude'], kdyn=kdyn)
            for k in ('k_dyn', 'loss_angle', 'damping', 'c_eq', 'energy', 'r_k', 'r_e'):
                assert r[k] == pytest.approx(s[k], rel=1e-12), (kdyn, k)
    for rh, re in zip(h, e, strict=True):
        # same energy and C_eq and R_E; eq24's ellipse under-states K_dyn (measured 1.03 % at 0.5 Hz and
        # 0.99 % at 1.3 Hz) and over-states R_K
        assert re['energy'] == pytest.approx(rh['energy'], rel=1e-12)
        assert re['c_eq'] == pytest.approx(rh['c_eq'], rel=1e-12) and re['r_e'] == pytest.approx(rh['r_e'], rel=1e-12)
        assert 0.0098 < 1 - re['k_dyn'] / rh['k_dyn'] < 0.0104
        assert re['r_k'] > rh['r_k']


def test_kdyn_in_the_table_and_eq24_refused_by_the_time_method(capsys):
    assert main(['props', '-f', '1Hz', '-a', '1mm', '--kdyn', 'eq24']) == 0
    assert 'K_dyn: eq24' in capsys.readouterr().out
    assert main(['props', '-f', '1Hz', '-a', '1mm', '--kdyn', 'eq24', '--method', 'time']) == 2
    err = capsys.readouterr().err
    assert '--kdyn eq24' in err and '--method analytic' in err


def test_kelvin_voigt_has_no_friction_ratios(capsys):
    r = run_json(capsys, '-p', 'seed000_case1', '-f', '0.5', '-a', '1mm')[0]
    assert r['c_eq'] == pytest.approx(243e3) and r['r_k'] is None and r['r_e'] is None


def test_table_output(capsys):
    assert main(['props', '-f', '1Hz', '-a', '1mm']) == 0
    out = capsys.readouterr().out
    assert 'K_dyn [N/m]' in out and 'C_eq [N s/m]' in out and 'K_dyn: harmonic' in out
    k = steady_state_properties(load_parameter_set('seed000_20C'), 1.0, 1e-3, kdyn='harmonic')['k_dyn']
    assert f'{k:12.5e}'.strip() in out


@pytest.mark.parametrize('argv,match', [(['-a', '1kN'], 'force'), (['-p', 'nope'], 'nope'),
                                        (['--temperature=30'], 'temperature'), (['-f', '0'], 'frequency')])
def test_bad_input_is_a_clear_error(capsys, argv, match):
    assert main(['props', *argv]) == 2
    assert match in capsys.readouterr().err
