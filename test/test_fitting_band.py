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

"""The measured band as a limit (issue 38 item 2): limit parameters carry the share the model's shape supplies
beyond the band, and a warning of their own when it exceeds their stated uncertainty."""
import pytest

from rubber_rig.fitting.blocks import BlockResult
from rubber_rig.fitting.data import _program_blocks, from_arrays
from rubber_rig.fitting.extrapolation import band_extrapolation, has_limit
from rubber_rig.fitting.identification import fit_model
from rubber_rig.fitting.simulate import EXACT_SENSORS, run_simulated
from rubber_rig.models.modelfile import named_model, parse_model

DECLARED = {'load_cell_gain_u': 0.0, 'load_cell_delay_u': 0.0, 'displacement_gain_u': 0.0, 'temperature_u': 0.2}


def _blocks(frequencies, amplitudes):
    return [BlockResult(index=i, start=0, stop=0, cycles=0, skipped_cycles=0, frequency=f, amplitude=a, mean=0.0,
                        k_dyn=0.0, loss_angle=0.0, damping=0.0, energy=0.0, c_eq=0.0)
            for i, (f, a) in enumerate((f, a) for a in amplitudes for f in frequencies)]


def test_limit_parameters_and_their_share_beyond_the_band():
    grid = _blocks((0.5, 1, 2, 4, 6, 8, 10, 14), (0.5e-3, 1e-3))
    tight = {k: {'relative_sigma': 0.002} for k in ('k0', 'k_inf', 'tau', 'alpha', 'x2', 'f_fmax')}
    # seed 000 at 20 degC on its own grid: K0 and K_inf are limits, 2.7 % and 3.5 % of them the Zener's shape
    spec = named_model('swing_arm_joint_20C')
    x = band_extrapolation(spec, spec.values(), grid, tight)
    assert x['_band'] == {'frequency': [0.5, 14], 'amplitude': [0.5e-3, 1e-3]}
    assert set(x) - {'_band'} == {'k0', 'k_inf'}            # tau, alpha and the friction act inside the band
    assert x['k0']['side'] == 'low' and 0.01 < x['k0']['share'] < 0.05 and not x['k0']['warn']
    assert x['k_inf']['side'] == 'high' and 0.01 < x['k_inf']['share'] < 0.05 and not x['k_inf']['warn']
    # at -40 degC (tau 15 ms, alpha 0.86) the grid reaches only 80 % of the way to K_inf: an extrapolation
    cold = named_model('swing_arm_joint_m40C')
    x = band_extrapolation(cold, cold.values(), grid, tight)
    assert x['k_inf']['warn'] and 0.15 < x['k_inf']['share'] < 0.25
    # ... unless the parameter's own interval is that wide already
    loose = {**tight, 'k_inf': {'relative_sigma': 0.1}}
    assert not band_extrapolation(cold, cold.values(), grid, loose)['k_inf']['warn']
    # a band reaching down to 0.005 Hz measures K0 itself: the band's edge sees nearly all of it, no limit left
    x = band_extrapolation(spec, spec.values(), _blocks((0.005, 1, 14), (0.5e-3, 1e-3)), tight)
    assert 'k0' not in x and 'k_inf' in x


def test_no_limit_where_the_models_stiffness_grows_without_end():
    """Seed 003's fractional branch c1 (j w)^beta grows as w^0.6 above its 1-50 Hz grid: there is no high-frequency
    limit whose share could be shape or data, so nothing is an extrapolation there (the true structure's fit warned
    'extrapolation' for c1 and beta, '75 % of the limit', before); a Zener relaxes to K_inf however slowly it gets
    there (alpha 0.3), and a dashpot grows without end too.
    """
    names = ('k3', 'k1', 'k2', 'c1', 'c2', 'alpha', 'beta', 'x2', 'f_fmax', 'k0', 'k_inf', 'tau')
    tight = {k: {'relative_sigma': 0.002} for k in names}
    s003 = named_model('seed003')
    x = band_extrapolation(s003, s003.values(), _blocks((1, 2, 5, 10, 20, 30, 40, 50), (0.2e-3, 0.3e-3, 0.5e-3)),
                           tight)
    assert x['_unbounded'] == ['high']
    assert not any(v['side'] == 'high' for k, v in x.items() if not k.startswith('_'))
    assert has_limit(s003, 1e3, 50.0, 0.5e-3, 0.0) is False and has_limit(s003, 1e-3, 1.0, 0.5e-3, 0.0) is True
    slow = named_model('swing_arm_joint_20C')
    values = {**slow.values(), 'alpha': 0.3, 'tau': 2e-3}
    assert has_limit(slow.with_values(values), 1e3, 40.0, 0.6e-3, 0.0)
    x = band_extrapolation(slow, values, _blocks((15, 22, 30, 40), (0.25e-3, 0.6e-3)), tight)
    assert '_unbounded' not in x and x['k0']['side'] == 'low'
    dashpot = named_model('swing_arm_joint_20C').to_dict()
    dashpot['elements'].append({'type': 'dashpot', 'c': '2 kNs/m'})
    assert not has_limit(parse_model(dashpot, 'dashpot'), 1e3, 14.0, 1e-3, 0.0)


def test_a_missing_fast_branch_on_a_narrow_high_band_is_an_extrapolation_of_k0():
    """Seed 000 plus a fast Maxwell branch (3 kN/mm, 3 kN s/m: 160 Hz) fitted with zener_berg on 15-40 Hz only:
    K0 comes out of the Zener shape carried down to 0 Hz; the fit must say so (k0's own warning)."""
    spec = named_model('swing_arm_joint_20C').to_dict()
    spec['elements'].append({'type': 'maxwell', 'k': '3 kN/mm', 'c': '3 kNs/m'})
    program = {'name': 'narrow', 'defaults': {'taper_cycles': 1, 'cycles': 30, 'mean': 0.0},
               'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.25 mm', '0.6 mm'],
                           'frequency': ['15 Hz', '22 Hz', '30 Hz', '40 Hz']}]}
    res, text, cfg = run_simulated(program, spec, 20.0, force_noise=20.0, seed=5, config_options=EXACT_SENSORS)
    run = from_arrays('narrow', 1 / res.sample_rate, res.displacement, res.force, block_index=res.block_index,
                      program_blocks=_program_blocks(text), temperature=20.0,
                      metadata={'specimen': spec, 'rig_config': cfg})
    fit = fit_model([run], 'zener_berg', **DECLARED)[0][0]
    found = [w for w in fit.warnings if w.code == 'extrapolation']
    assert any(w.parameters == ['k0'] for w in found), fit.warnings
    x = fit.uncertainty['k0']['extrapolation']
    # the fit made the Zener branch so broad (order at its bound) that K0 still acts far above the band
    assert x['band_hz'] == [15, 40] and x['share'] > 0.05
    assert '15-40 Hz' in next(w for w in found if w.parameters == ['k0'])
    assert fit.band['frequency'] == [15, 40]
    # the measured amplitudes: the actuator lags behind its setpoint at 40 Hz
    assert fit.as_dict()['band']['amplitude'] == pytest.approx([0.25e-3, 0.6e-3], rel=0.15)
    # and the misfit test, now measured against the right noise (20-50 Hz no longer reads the noise 8-15 % high),
    # sees the missing branch too
    assert 'misfit' in {w.code for w in fit.warnings}


def test_seed003_true_structure_on_its_grid_is_no_extrapolation():
    """The true seed-003 structure (orders fixed at the truth) on a 1-50 Hz grid: its stiffness keeps growing above
    the band, so there is no limit to extrapolate to, and the fit says nothing of the kind (it did: c1 and beta,
    '75 % of the high-frequency limit')."""
    spec = named_model('seed003').to_dict()
    program = {'name': 'seed003_grid', 'defaults': {'taper_cycles': 2, 'cycles': 8, 'mean': 0.0},
               'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.2 mm', '0.5 mm'],
                           'frequency': ['1 Hz', '2 Hz', '5 Hz', '10 Hz', '20 Hz', '30 Hz', '40 Hz', '50 Hz']}]}
    res, text, cfg = run_simulated(program, spec, 20.0, force_noise=20.0, seed=2, config_options=EXACT_SENSORS)
    run = from_arrays('s003', 1 / res.sample_rate, res.displacement, res.force, block_index=res.block_index,
                      program_blocks=_program_blocks(text), temperature=20.0,
                      metadata={'specimen': spec, 'rig_config': cfg})
    fixed = named_model('seed003').to_dict()
    fixed['elements'][1]['fixed'] = ['alpha', 'beta']
    fit = fit_model([run], fixed, **DECLARED)[0][0]
    assert 'extrapolation' not in {w.code for w in fit.warnings}, fit.warnings
    assert fit.band['no_limit'] == ['high']
    assert all(fit.as_dict()['covered'].values())
