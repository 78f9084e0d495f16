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
from rubber_rig.models import load_parameter_set, parameters_at_temperature, steady_state_properties
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
        assert set(r) == {'frequency', 'amplitude', 'k_dyn', 'loss_angle', 'damping', 'c_eq', 'energy', 'r_k', 'r_e'}
        s = steady_state_properties(p, r['frequency'], r['amplitude'])
        for k in r:
            assert r[k] == pytest.approx(s[k], rel=1e-12)
    assert {(r['frequency'], r['amplitude']) for r in rows} == {(0.5, 5e-4), (4.0, 5e-4), (0.5, 1e-3), (4.0, 1e-3)}


def test_temperature_and_grid(capsys):
    rows = run_json(capsys, '--temperature=-10degC', '--frequency-grid', '0.5Hz', '14Hz', '5', '-a', '1mm')
    assert len(rows) == 5
    np.testing.assert_allclose([r['frequency'] for r in rows], np.geomspace(0.5, 14, 5))
    s = steady_state_properties(parameters_at_temperature(-10), 14.0, 1e-3)
    assert rows[-1]['k_dyn'] == pytest.approx(s['k_dyn'], rel=1e-9)


def test_time_method_agrees_with_analytic(capsys):
    a = run_json(capsys, '-p', 'seed000_m20C', '-f', '4Hz', '-a', '1mm')[0]
    t = run_json(capsys, '-p', 'seed000_m20C', '-f', '4Hz', '-a', '1mm', '--method', 'time')[0]
    assert t['k_dyn'] == pytest.approx(a['k_dyn'], rel=1e-2)
    assert t['energy'] == pytest.approx(a['energy'], rel=5e-3)
    assert t['r_e'] == pytest.approx(a['r_e'], rel=1e-2)


def test_kelvin_voigt_has_no_friction_ratios(capsys):
    r = run_json(capsys, '-p', 'seed000_case1', '-f', '0.5', '-a', '1mm')[0]
    assert r['c_eq'] == pytest.approx(243e3) and r['r_k'] is None and r['r_e'] is None


def test_table_output(capsys):
    assert main(['props', '-f', '1Hz', '-a', '1mm']) == 0
    out = capsys.readouterr().out
    assert 'K_dyn [N/m]' in out and 'C_eq [N s/m]' in out
    k = steady_state_properties(load_parameter_set('seed000_20C'), 1.0, 1e-3)['k_dyn']
    assert f'{k:12.5e}'.strip() in out


@pytest.mark.parametrize('argv,match', [(['-a', '1kN'], 'force'), (['-p', 'nope'], 'nope'),
                                        (['--temperature=30'], 'temperature'), (['-f', '0'], 'frequency')])
def test_bad_input_is_a_clear_error(capsys, argv, match):
    assert main(['props', *argv]) == 2
    assert match in capsys.readouterr().err
