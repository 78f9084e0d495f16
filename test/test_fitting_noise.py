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

"""The noise estimate on every band (issue 38 item 1) and the two-sided misfit test.

Records are the seed-000 model (20 degC) run over tapered sine blocks with known white noise added (20 N on the
force, 0.2 um on the displacement), from 0.05 Hz to 100 Hz at 1 kHz and 10 kHz; one record comes from the
simulated rig (actuator, CAN path) at 20-50 Hz. The estimate must meet the truth within 3 % (and within 3 of
its own stated standard uncertainties), where the third-difference estimator it replaces is up to 80 % high.
"""
import math

import numpy as np
import pytest

from rubber_rig.fitting.blocks import noise_level, split_blocks
from rubber_rig.fitting.data import _program_blocks, from_arrays
from rubber_rig.fitting.identification import fit_model
from rubber_rig.fitting.misfit import misfit_sentence, misfit_test
from rubber_rig.fitting.noise import band_noise, run_noise
from rubber_rig.fitting.simulate import EXACT_SENSORS, run_simulated
from rubber_rig.models import build_model, load_parameter_set
from rubber_rig.models.modelfile import named_model

FORCE_NOISE, DISPLACEMENT_NOISE = 20.0, 0.2e-6


def model_record(frequencies, amplitude, fs, cycles=6, seed=0, force_noise=FORCE_NOISE,
                 displacement_noise=DISPLACEMENT_NOISE):
    """(RunData, blocks) of the seed-000 model over tapered sine blocks, white noise added (fixed seed).

    ``amplitude`` [m]: one for every block, or a tuple: every frequency at each of them.
    """
    p = load_parameter_set('swing_arm_joint_20C')
    amplitudes = amplitude if isinstance(amplitude, tuple) else (amplitude,)
    xs, bi = [], []
    for k, (f, amplitude) in enumerate((f, a) for a in amplitudes for f in frequencies):
        n = int(round((cycles + 2) * fs / f))
        t = np.arange(n) / fs
        env = np.ones(n)
        nt = int(round(fs / f))
        env[:nt] = 0.5 - 0.5 * np.cos(np.pi * np.arange(nt) / nt)
        env[n - nt:] = env[:nt][::-1]
        xs.append(amplitude * env * np.sin(2 * np.pi * f * t))
        bi.append(np.full(n, k))
    x = np.concatenate(xs)
    force = build_model(p, 1 / fs).run(x)
    rng = np.random.default_rng(seed)
    run = from_arrays('rec', 1 / fs, x + displacement_noise * rng.standard_normal(x.size),
                      force + force_noise * rng.standard_normal(x.size), block_index=np.concatenate(bi))
    rep = split_blocks(run.displacement, run.force, run.dt, block_index=run.block_index, settle_cycles=1,
                       recording='rec')
    assert len(rep.blocks) == len(frequencies) * len(amplitudes), rep.messages
    return run, rep.blocks


BANDS = [  # (sample rate [Hz], block frequencies [Hz], amplitude [m])
    (1000.0, (0.05, 0.1), 1e-3),
    (1000.0, (0.5, 2.0, 6.0, 14.0), 1e-3),
    (1000.0, (20.0, 30.0, 40.0, 50.0), 0.3e-3),
    (1000.0, (60.0, 80.0, 100.0), 0.1e-3),
    (10000.0, (0.05,), 1e-3),
    (10000.0, (0.5, 14.0), 1e-3),
    (10000.0, (20.0, 50.0, 100.0), 0.2e-3),
]


@pytest.mark.parametrize('fs,frequencies,amplitude', BANDS)
def test_noise_estimate_meets_the_truth_on_every_band_and_rate(fs, frequencies, amplitude):
    run, blocks = model_record(frequencies, amplitude, fs,
                               cycles=6 if min(frequencies) < 1 else 60 if min(frequencies) < 50 else 150)
    est = run_noise(run, blocks)
    for channel, truth in (('force', FORCE_NOISE), ('displacement', DISPLACEMENT_NOISE)):
        e = est[channel]
        assert e.method == 'harmonics_removed'
        assert e.variance_u < 0.06         # enough samples for the check to mean something (sigma to 3 %)
        # the stated uncertainty of sigma is half the variance's; the tolerance is 3 of them plus 1 % for the
        # estimator's remaining approximation (harmonics above MAX_HARMONICS, the MAD's calibration)
        assert e.sigma == pytest.approx(truth, rel=3 * 0.5 * e.variance_u + 0.01), (channel, e)


def test_noise_estimate_is_unbiased_on_a_high_band():
    """Eight records at 20-50 Hz: the mean estimate meets the truth to 1.5 % (the old one was 8-15 % high)."""
    sigmas = [run_noise(*model_record((20.0, 30.0, 40.0, 50.0), 0.3e-3, 1000.0, cycles=30, seed=s))['force'].sigma
              for s in range(8)]
    assert np.mean(sigmas) == pytest.approx(FORCE_NOISE, rel=0.015)


def test_the_third_difference_estimator_it_replaces_is_eaten_by_the_signal_at_high_frequency():
    run, blocks = model_record((60.0, 80.0, 100.0), 0.1e-3, 1000.0, cycles=30)
    assert noise_level(run.force) > 1.3 * FORCE_NOISE             # the signal leaks into the third differences
    assert noise_level(run.displacement) > 3 * DISPLACEMENT_NOISE
    assert run_noise(run, blocks)['force'].sigma == pytest.approx(FORCE_NOISE, rel=0.03)


def test_the_simulated_rig_at_20_to_50_hz():
    """The rig (80 Hz actuator, its distortion, the CAN path) at 20-50 Hz: the issue's 21.5-22.4 N for 20 N."""
    spec = named_model('swing_arm_joint_20C').to_dict()
    program = {'name': 'high_band', 'defaults': {'taper_cycles': 1, 'cycles': 30, 'mean': 0.0},
               'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.2 mm', '0.5 mm'],
                           'frequency': ['20 Hz', '30 Hz', '40 Hz', '50 Hz']}]}
    res, text, _ = run_simulated(program, spec, 20.0, force_noise=FORCE_NOISE, seed=3)
    run = from_arrays('rig', 1 / res.sample_rate, res.displacement, res.force, block_index=res.block_index,
                      program_blocks=_program_blocks(text))
    rep = split_blocks(run.displacement, run.force, run.dt, block_index=run.block_index,
                       program_blocks=run.program_blocks, recording='rig')
    est = run_noise(run, rep.blocks)
    assert noise_level(run.force) > 1.08 * FORCE_NOISE
    assert est['force'].sigma == pytest.approx(FORCE_NOISE, rel=0.03)
    # the displacement noise (0.2 um, plus the rig's quantisation) was 2.2 x high before
    assert noise_level(run.displacement) > 2 * DISPLACEMENT_NOISE
    assert est['displacement'].sigma == pytest.approx(DISPLACEMENT_NOISE, rel=0.04)


def test_removing_harmonics_from_white_noise_is_corrected_exactly():
    rng = np.random.default_rng(5)
    for n, f, dt in ((100, 50.0, 1e-3), (1000, 6.0, 1e-3), (4096, 0.05, 1e-4)):
        est = [band_noise(rng.normal(size=20 * n), dt, [(k * n, (k + 1) * n, f) for k in range(20)]).sigma
               for _ in range(4)]
        # 4 records of 20 windows: the mean is known to about 0.4-1 %; without the correction the 100-sample
        # windows at 50 Hz (19 harmonics, 40 of 100 dimensions removed) would come out about 10 % low
        assert np.mean(est) == pytest.approx(1.0, abs=0.025), (n, f)


def test_without_blocks_the_whole_record_is_used():
    rng = np.random.default_rng(2)
    x = 1000 * np.sin(2 * np.pi * np.arange(50000) * 1e-3) + rng.normal(0, 20, 50000)
    est = band_noise(x, 1e-3, [])
    assert est.method == 'third_differences' and est.sigma == pytest.approx(20, rel=0.02)
    assert 0 < est.variance_u < 0.05


def test_misfit_test_is_two_sided():
    dof = 5000
    assert not misfit_test(dof, dof, 0.01)['overstated'] and not misfit_test(dof, dof, 0.01)['misfit']
    low = misfit_test(0.85 * dof, dof, 0.01)          # -6 sigma: the noise estimate was too large
    assert low['overstated'] and not low['misfit'] and low['p_value_low'] < 1e-3
    high = misfit_test(1.15 * dof, dof, 0.01)
    assert high['misfit'] and not high['overstated']
    assert 'noise overstated' in misfit_sentence(low) and 'misfit' in misfit_sentence(high)
    assert math.isclose(misfit_test(dof, dof, 0.01)['p_value_two_sided'], 1.0)


def test_true_model_on_a_high_band_fits_to_the_noise():
    """A correct model over 20-50 Hz gives chi2/dof near 1 (0.83-0.93 with the old estimate)."""
    spec = named_model('swing_arm_joint_20C').to_dict()
    program = {'name': 'high_band', 'defaults': {'taper_cycles': 1, 'cycles': 20, 'mean': 0.0},
               'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.2 mm', '0.5 mm'],
                           'frequency': ['20 Hz', '30 Hz', '40 Hz', '50 Hz']}]}
    res, text, cfg = run_simulated(program, spec, 20.0, force_noise=FORCE_NOISE, seed=1,
                                   config_options=EXACT_SENSORS)
    run = from_arrays('rig', 1 / res.sample_rate, res.displacement, res.force, block_index=res.block_index,
                      program_blocks=_program_blocks(text), temperature=20.0,
                      metadata={'specimen': spec, 'rig_config': cfg})
    fit = fit_model([run], 'zener_berg')[0][0]
    assert abs(fit.misfit['z']) < 3, fit.misfit
    assert not fit.misfit['overstated'] and not fit.misfit['misfit']
    assert fit.noise['rig'] == pytest.approx(FORCE_NOISE, rel=0.05)
    assert fit.noise_estimates['rig']['force']['method'] == 'harmonics_removed'


def test_load_cell_noise_that_is_not_white_is_named_noise_overstated():
    """A load cell whose noise is blue (differenced white noise: an ADC's high-frequency hiss) fools any white
    noise estimator by the ratio of its high-frequency to its total power; the residual then sits below it and the
    two-sided test says so with its own code."""
    run, _ = model_record((0.5, 2.0, 6.0, 14.0), (0.5e-3, 1e-3), 1000.0, cycles=6, force_noise=0.0)
    rng = np.random.default_rng(7)
    e = rng.normal(0.0, 10.0, run.force.size + 1)
    run.force = run.force + np.diff(e)            # variance 2 x 10^2, but 3.5 x that in the third differences
    spec = named_model('swing_arm_joint_20C')
    run.metadata = {'specimen': spec.to_dict()}
    fit = fit_model([run], 'zener_berg', load_cell_gain_u=0.0, load_cell_delay_u=0.0, displacement_gain_u=0.0)[0][0]
    assert fit.misfit['overstated'], fit.misfit
    assert 'noise_overstated' in {w.code for w in fit.warnings}
