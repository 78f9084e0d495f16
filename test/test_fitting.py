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

"""Fitting: first-harmonic model properties, block splitting, identification from simulated-rig MCAP
recordings, degraded recordings (truncated, too few cycles, missing channel), YAML table, CLI."""
import json

import numpy as np
import pytest

from rubber_rig.fitting.blocks import split_blocks
from rubber_rig.fitting.data import from_arrays, load_run
from rubber_rig.fitting.identification import fit_model
from rubber_rig.fitting.paramfile import PARAM_NAMES
from rubber_rig.fitting.search import BlockTargets, coordinates, fit_harmonic_model
from rubber_rig.models import build_model, load_parameter_set, steady_state_properties
from rubber_rig.models.friction import berg_energy, berg_peak_force, friction_first_harmonic
from rubber_rig.models.modelfile import resolve_model

# A short version of the shipped dynamic_stiffness_grid program: 4 frequencies x 2 amplitudes, 6 cycles.
SHORT_PROGRAM = {
    'name': 'seed000_short', 'defaults': {'taper_cycles': 1, 'cycles': 6, 'mean': 0.0},
    'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.5 mm', '1 mm'],
                'frequency': ['0.5 Hz', '2 Hz', '6 Hz', '14 Hz']}]}
TOL = {'k0': 0.02, 'k_inf': 0.02, 'tau': 0.10, 'alpha': 0.10, 'x2': 0.10, 'f_fmax': 0.10}


def model_run(set_name, blocks, fs=1000.0, cycles=8, taper=1, noise_f=0.0, noise_x=0.0, seed=0):
    """Displacement/force arrays of tapered sine blocks through the seed-000 model (no rig)."""
    p = load_parameter_set(set_name)
    xs, bi = [], []
    for k, (f, a, ncyc) in enumerate(blocks):
        ncyc = cycles if ncyc is None else ncyc
        n = int(round((ncyc + 2 * taper) * fs / f))
        t = np.arange(n) / fs
        env = np.ones(n)
        nt = int(round(taper * fs / f))
        env[:nt] = 0.5 - 0.5 * np.cos(np.pi * np.arange(nt) / nt)
        env[n - nt:] = env[:nt][::-1]
        xs.append(a * env * np.sin(2 * np.pi * f * t))
        bi.append(np.full(n, k))
    x = np.concatenate(xs)
    force = build_model(p, 1 / fs).run(x)
    rng = np.random.default_rng(seed)
    return x + noise_x * rng.standard_normal(x.size), force + noise_f * rng.standard_normal(x.size), \
        np.concatenate(bi), p


@pytest.fixture(scope='module')
def recordings(tmp_path_factory):
    """Simulated-rig MCAP recordings (CAN path, actuator, 10 N load-cell noise) at 20 and -40 degC."""
    from rubber_rig.fitting.simulate import simulated_recording
    d = tmp_path_factory.mktemp('rec')
    return {t: simulated_recording(d / f'{name}.mcap', SHORT_PROGRAM, name, t, force_noise=10.0)
            for t, name in ((20.0, 'seed000_20C'), (-40.0, 'seed000_m40C'))}


# ---------------------------------------------------------------- model side, evaluated as measured
def test_berg_first_harmonic_matches_a_simulated_steady_loop_and_differs_from_eq21():
    from rubber_rig.fitting.metrics import window_properties
    f_fmax, x2, x0, fs, f = 4570.0, 1.41e-3, 0.5e-3, 2000.0, 1.0
    friction = build_model({'model': 'parallel', 'elements': [{'type': 'berg', 'f_fmax': f_fmax, 'x2': x2}]}, 1 / fs)
    n_per = int(fs / f)
    x = x0 * np.sin(2 * np.pi * f * np.arange(60 * n_per + 1) / fs)
    force = friction.run(x)
    # 20 steady cycles: harmonic_properties' drift column leaks the loop's odd harmonics into F1 by
    # ~0.6 % / cycles for this loop, so a long window keeps that below 0.05 %
    props = window_properties(x, force, 1 / fs, 40 * n_per, 60 * n_per, f)
    k = friction_first_harmonic(f_fmax, x2, x0)
    assert props['k_dyn'] == pytest.approx(abs(k), rel=1e-3)
    assert props['loss_angle'] == pytest.approx(np.angle(k), rel=2e-3)
    # only the first harmonic does work against a sine: loop area == Eq. 18 == pi x0^2 Im K
    assert props['energy_loop'] == pytest.approx(berg_energy(f_fmax, x2, x0), rel=2e-3)
    assert np.pi * x0 ** 2 * k.imag == pytest.approx(berg_energy(f_fmax, x2, x0), rel=1e-9)
    # seed 000 Eq. 21 (equal-peak ellipse) misses the first-harmonic storage stiffness by ~0.6 % here,
    # which is why the fit compares like with like
    e = berg_energy(f_fmax, x2, x0)
    f0 = berg_peak_force(f_fmax, x2, x0)
    k_fs_eq21 = f0 / x0 * np.sqrt(1 - (e / (np.pi * f0 * x0)) ** 2)
    assert abs(k_fs_eq21 / k.real - 1) > 0.004


def test_first_harmonic_properties_match_time_domain_runs_of_the_model():
    """Analytic first-harmonic K_dyn / C_eq vs the models library run in the time domain."""
    from rubber_rig.fitting.metrics import window_properties
    p = load_parameter_set('seed000_m20C')
    fs = 1000.0
    for f, a in ((0.5, 1e-3), (4.0, 0.5e-3), (14.0, 1e-3)):
        n_per = fs / f
        n = int(round(30 * n_per))
        x = a * np.sin(2 * np.pi * f * np.arange(n) / fs)
        force = build_model(p, 1 / fs).run(x)
        m = window_properties(x, force, 1 / fs, n - int(round(4 * n_per)), n - 1, f)
        pr = steady_state_properties(p, f, a, kdyn='harmonic')
        assert m['k_dyn'] == pytest.approx(pr['k_dyn'], rel=2e-3)
        assert m['c_eq'] == pytest.approx(pr['c_eq'], rel=1e-2)


def test_energy_agrees_with_the_models_eq_27_but_k_dyn_is_the_first_harmonic_not_eq_24():
    f, a = np.meshgrid([0.5, 1, 2, 4, 8, 14], [0.5e-3, 1e-3])
    for name, worst in (('seed000_20C', (0.001, 0.003)), ('seed000_m40C', (0.008, 0.013))):
        p = load_parameter_set(name)
        ours = steady_state_properties(p, f, a, kdyn='harmonic')
        paper = steady_state_properties(p, f, a, kdyn='eq24')
        np.testing.assert_allclose(ours['c_eq'], paper['c_eq'], rtol=1e-9)
        gap = np.max(np.abs(paper['k_dyn'] / ours['k_dyn'] - 1))
        assert worst[0] < gap < worst[1], (name, gap)


def test_harmonic_fit_recovers_parameters_from_exact_properties():
    p = load_parameter_set('seed000_0C').as_dict()
    f, a = np.meshgrid([0.5, 1, 2, 4, 8, 14], [0.5e-3, 1e-3])
    pr = steady_state_properties(load_parameter_set('seed000_0C'), f.ravel(), a.ravel(), kdyn='harmonic')
    zero = np.zeros(f.size)
    targets = BlockTargets(f.ravel(), a.ravel(), zero, pr['k_dyn'], pr['c_eq'], zero, zero)
    spec = resolve_model('zener_berg')
    coords = coordinates(spec, targets, 1e-3)
    z, ls = fit_harmonic_model(spec, coords, targets, seed=1)
    values = coords.values(z)
    for k in PARAM_NAMES:
        assert values[k] == pytest.approx(p[k], rel=1e-4), k
    assert ls.cost < 1e-12


# ---------------------------------------------------------------- block splitting
def test_blocks_from_block_index_skip_settling_cycles():
    blocks = [(0.5, 0.5e-3, None), (4.0, 1e-3, None), (14.0, 0.5e-3, None)]
    x, force, bi, _ = model_run('seed000_20C', blocks, noise_f=5.0, noise_x=0.2e-6)
    rep = split_blocks(x, force, 1e-3, block_index=bi, settle_cycles=3)
    assert [b.index for b in rep.blocks] == [0, 1, 2]
    for b, (f, a, _) in zip(rep.blocks, blocks, strict=False):
        assert b.frequency == pytest.approx(f, rel=5e-3)
        assert b.amplitude == pytest.approx(a, rel=5e-3)
        assert b.cycles == 8 - 3          # 8 steady cycles, 3 skipped for settling
        assert abs(b.mean) < 2e-6
        assert b.energy > 0 and b.c_eq > 0 and 0 < b.damping < 1
    assert rep.messages == []


def test_blocks_detected_without_metadata_match_the_indexed_ones():
    blocks = [(1.0, 1e-3, None), (3.0, 0.5e-3, None), (8.0, 1e-3, None), (12.0, 0.5e-3, None)]
    x, force, bi, _ = model_run('seed000_m20C', blocks, noise_f=5.0, noise_x=0.2e-6)
    indexed = split_blocks(x, force, 1e-3, block_index=bi).blocks
    detected = split_blocks(x, force, 1e-3).blocks
    assert len(detected) == len(indexed) == 4
    for d, i in zip(detected, indexed, strict=False):
        assert d.frequency == pytest.approx(i.frequency, rel=2e-3)
        assert d.amplitude == pytest.approx(i.amplitude, rel=2e-3)
        assert d.k_dyn == pytest.approx(i.k_dyn, rel=2e-3)
        assert d.c_eq == pytest.approx(i.c_eq, rel=2e-2)


def test_recording_without_block_index_is_split_by_detection():
    blocks = [(0.5, 1e-3, None), (2.0, 1e-3, None), (6.0, 0.5e-3, None), (14.0, 0.5e-3, None)]
    x, force, _, p = model_run('seed000_0C', blocks, noise_f=5.0, noise_x=0.2e-6)
    run = from_arrays('no_index', 1e-3, x, force, block_index=np.full(x.size, -1), temperature=0.0)
    assert run.block_index is None and any('detected' in m for m in run.messages)
    fits, messages = fit_model([run], 'zener_berg', method='harmonic')
    f = fits[0]
    assert [round(b.frequency, 2) for b in f.blocks] == [0.5, 2.0, 6.0, 14.0]
    assert [round(b.amplitude * 1e3, 2) for b in f.blocks] == [1.0, 1.0, 0.5, 0.5]
    assert all(b.cycles == 5 for b in f.blocks)


def test_block_with_too_few_cycles_is_reported_and_the_rest_is_fitted():
    blocks = [(f, a, None) for a in (0.5e-3, 1e-3) for f in (0.5, 2.0, 6.0, 14.0)] + [(5.0, 1e-3, 4)]
    x, force, bi, p = model_run('seed000_20C', blocks, noise_f=5.0)
    prog = [{'frequency': f, 'amplitude': a, 'waveform': 'sine'} for f, a, _ in blocks]
    run = from_arrays('short_block', 1e-3, x, force, block_index=bi, program_blocks=prog, temperature=20.0,
                      true_params=p.as_dict())
    fits, messages = fit_model([run], 'zener_berg', method='harmonic')
    assert any('block 8' in m and 'only 4 steady cycles' in m and 'skipped' in m for m in messages), messages
    assert len(fits[0].blocks) == 8
    for k in PARAM_NAMES:
        assert fits[0].parameters[k] == pytest.approx(p.as_dict()[k], rel=TOL[k]), k


# ---------------------------------------------------------------- identification from MCAP recordings
@pytest.mark.parametrize('temperature', [20.0, -40.0])
def test_fit_of_simulated_rig_recording_recovers_the_specimen(recordings, temperature):
    run = load_run(recordings[temperature])
    assert run.temperature == temperature and run.true_params is not None
    fits, messages = fit_model([run], 'zener_berg', method='time')
    assert messages == []
    f = fits[0]
    assert f.temperature == temperature and len(f.blocks) == 8
    # at -40 degC (tau 15 ms, alpha 0.86) the 0.5-14 Hz grid reaches only ~80 % of the way to K_inf: the rest is
    # the Zener shape, and the fit says so (issue 38: the measured band is a limit); nothing else is wrong
    expected = [['k_inf']] if temperature < 0 else []
    assert [w.parameters for w in f.warnings] == expected and all(w.code == 'extrapolation' for w in f.warnings)
    for k in PARAM_NAMES:
        assert f.parameters[k] == pytest.approx(run.true_params[k], rel=TOL[k]), k
    ek, ec = f.max_errors('simulated')
    assert ek < 0.01 and ec < 0.05
    ak, ac = f.max_errors('analytic')
    assert ak < 0.01 and ac < 0.05
    # uncertainty: finite, positive, and the truth within 4 sigma
    for k in PARAM_NAMES:
        sig = f.uncertainty[k]['relative_sigma']
        assert 0 < sig < 0.1
        assert abs(f.parameters[k] / run.true_params[k] - 1) < 4 * sig, k


def test_harmonic_method_on_recording_meets_the_targets(recordings):
    run = load_run(recordings[20.0])
    f = fit_model([run], 'zener_berg', method='harmonic')[0][0]
    for k in PARAM_NAMES:
        assert f.parameters[k] == pytest.approx(run.true_params[k], rel=TOL[k]), k
    # the first harmonics of ideal sines cannot see the 80 Hz actuator's distortion of the 14 Hz blocks, which
    # 10 N of load-cell noise resolves (K_dyn off by 0.04 %, 3.6 sigma): chi2/dof about 6 against the
    # blocks' noise, and the fit says so (the time-domain fit sees the measured displacement: test above)
    assert 1.0 < f.chi2_per_dof < 10
    assert any(w.startswith('misfit beyond noise') for w in f.warnings) == (f.chi2_per_dof > 1.5)


def test_two_temperatures_give_one_model_file_each_loadable_by_the_models(recordings, tmp_path, capsys):
    from rubber_rig.cli.main import main
    from rubber_rig.models.modelfile import load_model_file
    runs = [load_run(p) for p in recordings.values()]
    fits, _ = fit_model(runs, 'zener_berg', method='harmonic')
    assert [f.temperature for f in fits] == [-40.0, 20.0]
    assert main(['fit', *map(str, recordings.values()), '--method', 'harmonic', '-o', str(tmp_path / 'p.yaml'),
                 '--no-progress']) == 0
    capsys.readouterr()
    for f in fits:
        tag = 'm40C' if f.temperature < 0 else '20C'
        spec = load_model_file(tmp_path / f'p_{tag}.yaml')
        model = build_model(spec, 1e-3)                        # what element_model and the sim rig load
        assert model.run(np.zeros(3)).shape == (3,)
        for k in PARAM_NAMES:
            assert spec.values()[k] == pytest.approx(f.parameters[k], rel=1e-5), k


# ---------------------------------------------------------------- degraded recordings
def test_truncated_recording_fits_what_is_there(recordings):
    run = load_run(recordings[20.0])
    cut = int(run.displacement.size * 0.8)          # the tail of the 1 mm / 6 and 14 Hz blocks is lost
    run.displacement, run.force, run.block_index = run.displacement[:cut], run.force[:cut], run.block_index[:cut]
    fits, messages = fit_model([run], 'zener_berg', method='harmonic')
    assert any('truncated' in m for m in messages), messages
    n = len(fits[0].blocks)
    assert 5 <= n < 8
    for k in ('k0', 'k_inf'):
        assert fits[0].parameters[k] == pytest.approx(run.true_params[k], rel=0.02)


def test_truncated_mcap_file_fits_what_was_written(recordings, tmp_path):
    data = recordings[20.0].read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:int(len(data) * 0.8)])     # writer killed: no summary, tail missing
    run = load_run(cut)
    assert any('truncated' in m for m in run.messages)
    fits, messages = fit_model([run], 'zener_berg', method='harmonic')
    assert any('truncated' in m for m in messages)
    assert 5 <= len(fits[0].blocks) < 8
    for k in ('k0', 'k_inf'):
        assert fits[0].parameters[k] == pytest.approx(run.true_params[k], rel=0.02)


def test_temperature_with_too_few_blocks_is_skipped_and_the_others_fitted():
    x, force, bi, p = model_run('seed000_m20C', [(f, a, None) for a in (0.5e-3, 1e-3) for f in (0.5, 3.0, 12.0)])
    good = from_arrays('good', 1e-3, x, force, block_index=bi, temperature=-20.0)
    x2_, f2_, bi2, _ = model_run('seed000_0C', [(1.0, 1e-3, None), (4.0, 1e-3, None)])
    sparse = from_arrays('sparse', 1e-3, x2_, f2_, block_index=bi2, temperature=0.0)
    fits, messages = fit_model([good, sparse], 'zener_berg', method='harmonic')
    assert [f.temperature for f in fits] == [-20.0]
    assert any(m.startswith('0 degC: not fitted: 2 usable blocks give 4 numbers') and '6 free parameters' in m
               for m in messages), messages
    with pytest.raises(ValueError, match='nothing could be fitted.*record more blocks'):
        fit_model([sparse], 'zener_berg', method='harmonic')


def test_missing_channels(recordings, tmp_path):
    from rubber_rig.fitting.simulate import run_simulated, write_recording
    prog = {'name': 'tiny', 'defaults': {'taper_cycles': 1, 'cycles': 6},
            'blocks': [{'waveform': 'sine', 'amplitude': '1 mm', 'frequency': ['2 Hz', '6 Hz']}]}
    spec = {'model': 'seed000', 'parameter_set': 'seed000_20C'}
    result, text, cfg = run_simulated(prog, spec, 20.0)
    no_force = write_recording(tmp_path / 'no_force.mcap', result, text, spec, 20.0, cfg,
                               channels=('displacement', 'setpoint'))
    no_disp = write_recording(tmp_path / 'no_disp.mcap', result, text, spec, 20.0, cfg,
                              channels=('force', 'setpoint'))
    runs = [load_run(no_force), load_run(no_disp), load_run(recordings[20.0])]
    assert not runs[0].usable()
    assert runs[1].usable()                              # falls back to the setpoint
    fits, messages = fit_model(runs, 'zener_berg', method='harmonic')
    assert any('no_force.mcap' in m and 'no force channel' in m for m in messages), messages
    assert any('no_disp.mcap' in m and 'using the setpoint' in m for m in messages), messages
    assert len(fits) == 1 and set(fits[0].runs) == {runs[1].name, runs[2].name}
    assert len(fits[0].blocks) == 2 + 8


def test_cli_fit_json_and_yaml(recordings, tmp_path, capsys):
    from rubber_rig.cli.main import main
    out = tmp_path / 'p.yaml'
    assert main(['fit', str(recordings[-40.0]), '-o', str(out), '--method', 'harmonic', '--json',
                 '--no-progress']) == 0
    data = json.loads(capsys.readouterr().out)
    f = data['fits'][0]
    assert f['temperature'] == -40.0 and len(f['blocks']) == 8
    assert set(f['parameters']) == set(PARAM_NAMES)
    assert set(f['errors']) == set(PARAM_NAMES) and all(abs(v) < TOL[k] for k, v in f['errors'].items())
    assert {'e_k', 'e_c'} <= set(f['blocks'][0]['simulated'])
    assert data['model'] == 'zener_berg' and isinstance(data['warnings'], list) and data['chi2_per_dof'] > 0
    assert set(data['uncertainty']) == set(PARAM_NAMES)
    from rubber_rig.models.modelfile import load_model_file
    fitted = load_model_file(out)
    assert fitted.values() == pytest.approx(f['parameters'], rel=1e-12)


def test_cli_fit_bad_input_is_a_clear_error(tmp_path, capsys):
    from rubber_rig.cli.main import main
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(b'not an mcap file at all')
    assert main(['fit', str(bad), str(tmp_path / 'missing.mcap'), '--no-progress']) == 2
    err = capsys.readouterr().err
    assert 'bad.mcap' in err and 'missing.mcap' in err and 'Traceback' not in err
