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

"""Diagnoses named (issue 38 items 3-5): the temperature cross-check, non-stationarity, outliers, saturation, and
intervals honest at their edges.

One simulated-rig record (seed 000 at 20 degC, 0.5-14 Hz x 0.5/1 mm, 20 N load-cell noise, fixed seed) is fitted
clean and with one thing wrong at a time: the specimen softening by 3 % over the test (heating), spikes on 0.1 % of
the force samples, the load cell clipped at 80 % of its largest force, and a metadata temperature of 20 degC on a
record whose temperature channel reads 0 degC. Each must carry its own warning code; the clean record none of them.
"""
import json
import math

import numpy as np
import pytest

from rubber_rig.cli.fit import _jsonable
from rubber_rig.fitting.budget import add_budget
from rubber_rig.fitting.data import _program_blocks, from_arrays
from rubber_rig.fitting.diagnoses import drift_within_blocks, flat_tops
from rubber_rig.fitting.identification import fit_model
from rubber_rig.fitting.misfit import row_threshold
from rubber_rig.fitting.simulate import EXACT_SENSORS, run_simulated
from rubber_rig.fitting.temperature import resolve, temperature_sentences
from rubber_rig.models.modelfile import named_model

PROGRAM = {'name': 'grid', 'defaults': {'taper_cycles': 1, 'cycles': 7, 'mean': 0.0},
           'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.5 mm', '1 mm'],
                       'frequency': ['0.5 Hz', '2 Hz', '6 Hz', '14 Hz']}]}
NAMED = ('non_stationary', 'outliers', 'saturation', 'temperature_disagrees')
DECLARED = {'load_cell_gain_u': 0.0, 'load_cell_delay_u': 0.0, 'displacement_gain_u': 0.0, 'temperature_u': 0.2}


@pytest.fixture(scope='module')
def record():
    spec = named_model('swing_arm_joint_20C').to_dict()
    res, text, cfg = run_simulated(PROGRAM, spec, 20.0, force_noise=20.0, seed=4, config_options=EXACT_SENSORS)
    return {'x': np.asarray(res.displacement), 'f': np.asarray(res.force), 'bi': np.asarray(res.block_index),
            'dt': 1 / res.sample_rate, 'program': _program_blocks(text), 'spec': spec, 'cfg': cfg}


def _fit(record, force=None, **kw):
    kw.setdefault('temperature', 20.0)
    run = from_arrays('rec', record['dt'], record['x'], record['f'] if force is None else force,
                      block_index=record['bi'], program_blocks=record['program'],
                      metadata={'specimen': record['spec'], 'rig_config': record['cfg']}, **kw)
    return fit_model([run], 'zener_berg', **DECLARED)[0][0]


def _codes(fit):
    return {w.code for w in fit.warnings}


def test_clean_record_has_none_of_the_named_diagnoses(record):
    fit = _fit(record)
    assert not (_codes(fit) & set(NAMED)), fit.warnings
    assert all(fit.as_dict()['covered'].values())
    drift = fit.diagnoses['drift']
    assert drift and not drift['K_dyn']['drift'] and not drift['C_eq']['drift']
    assert fit.temperature_records['rec']['source'] == 'metadata'
    # the displacement noise's bias on Berg's parameters is in the budget (fitting.inputnoise): 5.0 and 5.7 % per um
    # of noise, about 1 % at 0.2 um; nothing on the viscoelastic parameters
    sigma_x = fit.noise_estimates['rec']['displacement']['sigma']
    assert sigma_x == pytest.approx(0.2e-6, rel=0.1)
    x2 = fit.parameters['x2']
    budget = {k: fit.uncertainty[k]['budget'] for k in fit.parameters}
    assert budget['x2']['displacement_noise'] == pytest.approx(5.0e4 * sigma_x * x2, rel=1e-9)
    f_fmax = fit.parameters['f_fmax']
    assert budget['f_fmax']['displacement_noise'] == pytest.approx(5.7e4 * sigma_x * f_fmax, rel=1e-9)
    assert all('displacement_noise' not in budget[k] for k in ('k0', 'k_inf', 'tau', 'alpha'))
    total = math.sqrt(sum(v ** 2 for v in budget['x2'].values() if v is not None))
    assert fit.uncertainty['x2']['sigma'] == pytest.approx(total, rel=1e-12)


def test_heating_is_named_non_stationary(record):
    t = np.arange(record['f'].size) * record['dt']
    fit = _fit(record, force=record['f'] * (1 - 0.03 * t / t[-1]))     # 3 % softer by the end of the test
    assert 'non_stationary' in _codes(fit), fit.warnings
    # e = model / measured - 1 grows as the specimen softens: by 3 % over the record, measured inside the blocks
    # over the span from the first analysed cycle to the last (most of the record)
    drift = fit.diagnoses['drift']
    # (e = 1 / (1 - 0.03 t / T) - 1: its slope runs from 0.03 / T to 1.06 x that by the end)
    expected = 0.03 * drift['duration'] / t[-1]
    se = drift['K_dyn']['se']
    assert expected - 4 * se < drift['K_dyn']['change'] < 1.07 * expected + 4 * se
    assert 'relative to the model' in next(w for w in fit.warnings if w.code == 'non_stationary')


def test_a_missing_branch_is_a_misfit_not_a_drift(record):
    """Seed 000 plus a Maxwell branch (2 kN/mm, 5 kN s/m) fitted with zener_berg: the model errs by a curved
    pattern in ln f, the same in every cycle of a block; it must be named a misfit, not non_stationary (it was:
    regressed across blocks on time, the curvature aliased onto the block order)."""
    spec = named_model('swing_arm_joint_20C').to_dict()
    spec['elements'].append({'type': 'maxwell', 'k': '2 kN/mm', 'c': '5 kNs/m'})
    res, text, cfg = run_simulated(PROGRAM, spec, 20.0, force_noise=20.0, seed=4, config_options=EXACT_SENSORS)
    run = from_arrays('maxwell', 1 / res.sample_rate, res.displacement, res.force, block_index=res.block_index,
                      program_blocks=_program_blocks(text), temperature=20.0,
                      metadata={'specimen': spec, 'rig_config': cfg})
    fit = fit_model([run], 'zener_berg', **DECLARED)[0][0]
    assert 'misfit' in _codes(fit) and 'non_stationary' not in _codes(fit), fit.warnings
    drift = fit.diagnoses['drift']
    assert abs(drift['K_dyn']['change']) < 0.005 and not drift['C_eq']['drift']


def test_spikes_are_named_outliers(record):
    rng = np.random.default_rng(11)
    f = record['f'].copy()
    hit = rng.choice(f.size, size=f.size // 1000, replace=False)          # 0.1 % of the samples
    f[hit] += rng.choice([-1.0, 1.0], hit.size) * 600.0                    # 30 noise sigmas
    fit = _fit(record, force=f)
    assert 'outliers' in _codes(fit), fit.warnings
    test = fit.diagnoses['outliers']['rec']['force']
    assert test['count'] >= 3 and test['largest'] > 20
    assert 'saturation' not in _codes(fit)


def test_a_clipped_load_cell_is_named_saturation(record):
    limit = 0.8 * np.max(np.abs(record['f']))
    fit = _fit(record, force=np.clip(record['f'], -limit, limit))
    assert 'saturation' in _codes(fit), fit.warnings
    flat = fit.diagnoses['saturation']['rec']['force']
    assert flat['level'] == pytest.approx(limit if flat['side'] == 'max' else -limit) and flat['runs'] >= 2


def test_a_wrong_temperature_label_is_named_and_the_channel_is_used(record):
    channel = np.full(record['f'].size, 0.0) + np.random.default_rng(1).normal(0, 0.05, record['f'].size)
    fit = _fit(record, temperature=20.0, temperature_channel=channel)
    assert 'temperature_disagrees' in _codes(fit)
    text = next(w for w in fit.warnings if w.code == 'temperature_disagrees')
    assert '20 degC' in text and '0 degC' in text and 'the fit used the channel' in text
    assert fit.temperature == pytest.approx(0.0, abs=0.5)
    assert fit.temperature_records['rec']['source'] == 'channel'


def test_temperature_statements_compared_with_their_uncertainties():
    agree = resolve(20.0, np.full(100, 20.4), sensor_u=0.2)
    assert agree['disagreement'] is None and agree['source'] == 'channel' and agree['value'] == pytest.approx(20.4)
    apart = resolve(20.0, np.full(100, 23.0), sensor_u=0.2)
    assert apart['disagreement']['difference'] == pytest.approx(-3.0)
    assert resolve(20.0, None)['source'] == 'metadata'
    assert resolve(20.0, np.full(10, 0.0), override=5.0)['value'] == 5.0
    # a model whose fixed values belong to 20 degC, used on a 0 degC record
    text = temperature_sentences(resolve(None, np.full(10, 0.0), sensor_u=0.2), 20.0, ['alpha'], 'r')
    assert text and 'alpha' in text[0] and '20 degC' in text[0]
    assert not temperature_sentences(resolve(None, np.full(10, 0.0), sensor_u=0.2), 20.0, [], 'r')


def test_flat_tops_only_where_a_channel_holds_its_extreme():
    rng = np.random.default_rng(0)
    x = 1000 * np.sin(2 * np.pi * np.arange(5000) / 500) + rng.normal(0, 10, 5000)
    assert flat_tops(x) is None
    assert flat_tops(np.clip(x, -2000, 900))['side'] == 'max'
    assert flat_tops(np.round(x / 5) * 5) is None       # a quantised noisy signal does not hold its extreme
    # a quiet channel read to 0.1 um holds a slow sine's peak for many samples, but steps onto it by one quantum
    slow = np.round(1e-3 * np.sin(2 * np.pi * 0.5 * np.arange(6000) * 1e-3) / 1e-7) * 1e-7
    assert flat_tops(slow) is None
    assert flat_tops(np.clip(slow, -2e-3, 0.9e-3))['side'] == 'max'


class _Run:
    def __init__(self, x, f, dt):
        self.displacement, self.force, self.dt = x, f, dt


class _Block:
    def __init__(self, start, stop, cycles, frequency, amplitude):
        self.start, self.stop, self.cycles, self.frequency, self.amplitude = start, stop, cycles, frequency, amplitude
        self.recording = 'r'


def test_drift_is_measured_inside_the_blocks():
    """A force that scales down in time drifts inside every block; a force whose error depends on frequency alone
    (a different gain per block, constant inside it) does not, however it lines up with the block order."""
    dt, rng = 1e-3, np.random.default_rng(3)
    freqs, amps = [1, 2, 4, 8, 1, 2, 4, 8], [0.5e-3] * 4 + [1e-3] * 4
    x_parts, blocks, start = [], [], 0
    for f, a in zip(freqs, amps, strict=True):
        n = int(round(8 / f / dt))                       # 8 cycles at 1 kHz
        x_parts.append(a * np.sin(2 * np.pi * f * np.arange(n) * dt))
        blocks.append(_Block(start, start + n, 8, f, a))
        start += n
    x = np.concatenate(x_parts)
    k = 14e6
    model = k * x
    t = np.arange(x.size) * dt
    pattern = np.concatenate([np.full(b.stop - b.start, 1 + 0.02 * np.log(b.frequency) ** 2) for b in blocks])
    noise = rng.normal(0.0, 20.0, x.size)
    heating = drift_within_blocks(blocks, {'r': _Run(x, model * (1 - 0.03 * t / t[-1]) + noise, dt)}, {'r': model},
                                  {'r': 20.0})
    assert heating['K_dyn']['drift'] and heating['blocks'] == 8
    # e = 1 / (1 - 0.03 t / T) - 1: its slope runs from 0.03 / T to 1.06 x that by the end
    assert 1.0 < heating['K_dyn']['change'] / (0.03 * heating['duration'] / t[-1]) < 1.07
    curved = drift_within_blocks(blocks, {'r': _Run(x, model * pattern + noise, dt)}, {'r': model}, {'r': 20.0})
    assert not curved['K_dyn']['drift'] and abs(curved['K_dyn']['change']) < 3 * curved['K_dyn']['se']
    short = [_Block(b.start, b.stop, 3, b.frequency, b.amplitude) for b in blocks]     # 3 cycles: no trend to see
    assert drift_within_blocks(short, {'r': _Run(x, model, dt)}, {'r': model}, {'r': 20.0}) == {}


def test_intervals_unbounded_sides_are_inf_with_a_reason_and_never_null_in_json():
    unc = {'k0': {'value': 2e5, 'sigma': 1e6, 'interval_95': [2e5 - 2e6, 2e5 + 2e6]},
           'tau': {'value': 0.04, 'sigma': 0.004, 'interval_95': [0.032, 0.048]}}
    add_budget(unc, {'k0': 'log', 'tau': 'log'}, {'k0': 'stiffness', 'tau': 'time'}, {'gain_u': 0.0})
    assert unc['k0']['interval_95'] == [0.0, math.inf]
    assert 'unbounded' in unc['k0']['interval_note'] and 'interval_note' not in unc['tau']
    text = json.dumps(_jsonable(unc))
    assert '"inf"' in text and 'null' not in text


def test_row_tests_are_corrected_for_their_number():
    assert row_threshold(1) == pytest.approx(3.0, abs=0.01)
    assert 3.8 < row_threshold(30) < 4.0           # 15 table rows, K_dyn and C_eq each
    # the family-wise false alarm of a correct table stays at 0.27 % however many rows
    from scipy.stats import norm
    for m in (2, 30, 200):
        assert 1 - (1 - 2 * norm.sf(row_threshold(m))) ** m == pytest.approx(0.0027, rel=1e-6)


def test_berg_input_noise_scales_with_the_noise_and_x2():
    """The Type B term of fitting.inputnoise: u(x2) / x2 = 5.0 %/um and u(F_fmax) / F_fmax = 5.7 %/um of displacement
    noise, only for free Berg parameters, nothing without displacement noise."""
    from rubber_rig.fitting.inputnoise import berg_input_noise
    spec = named_model('swing_arm_joint_20C')
    values = spec.values()
    u = berg_input_noise(spec, values, 0.2e-6)
    assert set(u) == {'x2', 'f_fmax'}
    assert u['x2'] / values['x2'] == pytest.approx(0.010, rel=1e-9)         # the stiff specimen's +0.98 +- 0.25 %
    assert u['f_fmax'] / values['f_fmax'] == pytest.approx(0.0114, rel=1e-9)  # and +1.14 +- 0.30 %
    assert berg_input_noise(spec, values, 0.4e-6)['x2'] == pytest.approx(2 * u['x2'])
    assert berg_input_noise(spec, values, 0.0) == {}
    assert berg_input_noise(spec, {'x2': values['x2']}, 0.2e-6).keys() == {'x2'}           # F_fmax fixed
    s003 = named_model('seed003')
    assert set(berg_input_noise(s003, s003.values(), 0.2e-6)) == {'x2', 'f_fmax'}
