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

"""Acceptance benchmark of identification: does every fit tell the truth.

For each case a specimen is simulated with `rubber-rig simulate` (simulated rig, CAN path, 80 Hz actuator,
20 N load-cell noise, 0.2 um displacement noise, 1 kHz) over ``--seeds`` noise seeds, recorded to MCAP and
fitted with `rubber-rig fit`'s code with the true model and the seed-000 model. Per case and fitted model
the table reports the largest median |parameter error|, the share of (seed, parameter) pairs whose 95 %
interval covers the truth (worst parameter and all), the median chi2/dof, the share of seeds with at least
one warning, how often AIC and BIC pick the true model, and the slowest fit.

Cases: seed 000 at 20, 0, -20, -40 degC; seed 000 + cubic spring (6e11 N/m^3); a seed-003-style specimen
(cubic spring + two-order fractional + Berg, sine grid 1-50 Hz x 0.2/0.3/0.5 mm); seed 004's pad at Table 1's
15 cases (0.3, 0.5, 0.7 mm about -0.9, -1.1, -1.3 mm, 2-10 Hz; operating-point spring with K1(f, A) and K3(f, A)
interpolating Table 2 + elliptic damping; the true structure is identified per block); load cell 0.2 ms late,
undeclared (fitted with the declared-sensor default and with --estimate-delay) and declared; load cell +1 % gain
undeclared, declared as 1 +- 1 %, and corrected;
load cell gain 0.97 undeclared and declared as 1 +- 3 %; seed 000 + a Maxwell branch (2 kN/mm, 5 kN s/m)
fitted with the true structure, with seed 000's model and with seed 000's model and a free delay (a
model error passed off as a sensor delay); seed 000 + a dashpot (2 kN s/m) fitted with and without it;
seed 000's viscoelastic part with a velocity-driven friction law (tanh Coulomb, seed 002 Eq. 46) instead of
Berg's, fitted with Berg's; a load-cell offset of 200 N and zero drifts of 2 N/s and 20 N/s (not declared:
the per-block offsets absorb an offset and a slow drift, so those cases must cover the truth without a
warning; a fast drift must warn); 3-cycle blocks fitted with --settle-cycles 1; only 0.5-4 Hz with
the cubic spring and the late load cell. The seed-003 specimen is fitted with its fractional orders fixed at
the truth (identifiable) and free (six viscoelastic parameters: more than a 1-50 Hz grid pins down, so the fit
must warn). Unless a case says "undeclared", the recording declares the simulated load cell's calibration
(exact: --record-calibration).

Issue 38's cases (each kind, none a copy of the issue's own): seed 000 at 0 degC on a high band only (25-60 Hz,
the true model: K_inf and the friction trade off there, warned ``identifiability``, all covered); seed 000 plus a fast
Maxwell branch (3 kN/mm, 3 kN s/m) on 15-40 Hz fitted with zener_berg (``extrapolation`` and ``misfit``); a
specimen softening by 4 % over the test (``non_stationary``); spikes of 40 sigma on 0.05 % of the force samples
(``outliers``); a load cell clipped at 85 % of its largest force (``saturation``); a 0 degC record labelled
20 degC in its metadata, its channel right (``temperature_disagrees``); a load cell with blue noise (the
differences of 15 N white noise: a white-noise estimator reads it 1.3 x high, ``noise_overstated``). The
record-level faults are applied to the simulated recording after it is read (``post`` in CASES): the simulated
rig has no such sensor faults.

Per case and fitted model the table also gives the share of seeds carrying each warning code, the number
of seeds whose truth fell outside a 95 % interval (or more than 3 sigma away) without a single warning, and the
slowest fit's CPU time (process time of the worker: the < 10 s per fit goal).

Targets: true model -> every parameter inside its 95 % interval in >= 90 % of the seeds and no warning;
wrong model, undeclared or wrong sensor -> a warning with the right code in >= 95 % of the seeds; no
uncovered truth without a warning; AIC/BIC pick the true model.

    .venv/bin/python benchmarks/bench_identification.py [--seeds 20] [--cases all|NAME,...] [--jobs 2]
"""
from __future__ import annotations

import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); before rclpy loads
# one BLAS thread per fit (before numpy loads): the fits' matrices are small, and a multithreaded OpenBLAS spins
# its threads on them; on this 2-core machine under load that cost 2.6 x the CPU of one thread per fit (an
# 8-parameter fit on 20-50 Hz: 4.7 s against 1.8 s) and no wall time. The jobs run in parallel instead.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
import argparse  # noqa: E402 - after the environment above, which numpy reads when it loads
import contextlib  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from multiprocessing import Pool  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import yaml  # noqa: E402
from scipy.stats import binom  # noqa: E402

GRID = 'dynamic_stiffness_grid'
SEED003_PROGRAM = {'name': 'seed003_grid', 'defaults': {'taper_cycles': 2, 'cycles': 8, 'mean': 0.0},
                   'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.2 mm', '0.3 mm', '0.5 mm'],
                               'frequency': ['1 Hz', '2 Hz', '5 Hz', '10 Hz', '20 Hz', '30 Hz', '40 Hz',
                                             '50 Hz']}]}
LOWBAND_PROGRAM = {'name': 'low_band', 'defaults': {'taper_cycles': 2, 'cycles': 8, 'mean': 0.0},
                   'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.5 mm', '1 mm'],
                               'frequency': ['0.5 Hz', '1 Hz', '2 Hz', '3 Hz', '4 Hz']}]}
# seed 004 Table 1: 15 cases, each amplitude about its own preload (0.3 mm at -0.9 mm, 0.5 at -1.1, 0.7 at -1.3)
PAD_PROGRAM = {'name': 'pad_table1', 'defaults': {'taper_cycles': 2, 'cycles': 10}, 'blocks': [
    {'name': 'preload_0.9mm', 'waveform': 'ramp', 'target': '-0.9 mm', 'rate': '0.5 mm/s'},
    {'name': 'settle_1', 'waveform': 'hold', 'duration': '2 s'},
    {'name': 'pad', 'waveform': 'sine', 'mean': '-0.9 mm', 'amplitude': '0.3 mm',
     'frequency': ['2 Hz', '4 Hz', '6 Hz', '8 Hz', '10 Hz']},
    {'name': 'preload_1.1mm', 'waveform': 'ramp', 'target': '-1.1 mm', 'rate': '0.5 mm/s'},
    {'name': 'settle_2', 'waveform': 'hold', 'duration': '2 s'},
    {'name': 'pad', 'waveform': 'sine', 'mean': '-1.1 mm', 'amplitude': '0.5 mm',
     'frequency': ['2 Hz', '4 Hz', '6 Hz', '8 Hz', '10 Hz']},
    {'name': 'preload_1.3mm', 'waveform': 'ramp', 'target': '-1.3 mm', 'rate': '0.5 mm/s'},
    {'name': 'settle_3', 'waveform': 'hold', 'duration': '2 s'},
    {'name': 'pad', 'waveform': 'sine', 'mean': '-1.3 mm', 'amplitude': '0.7 mm',
     'frequency': ['2 Hz', '4 Hz', '6 Hz', '8 Hz', '10 Hz']},
    {'name': 'unload', 'waveform': 'ramp', 'target': '0 mm', 'rate': '0.5 mm/s'}]}


def _seed000(temp_name, extra=()):
    from rubber_rig.models.modelfile import named_model
    d = named_model(f'swing_arm_joint_{temp_name}').to_dict()
    d['elements'] += list(extra)
    return d


def _named(name):
    from rubber_rig.models.modelfile import named_model
    return named_model(name).to_dict()


def _fixed_orders():
    d = _named('seed003')
    d['elements'][1]['fixed'] = ['alpha', 'beta']
    return d


def _pad_specimen():
    """Seed 004's pad as a model file: :func:`rubber_rig.models.seed004.seed004_pad_spec`'s K1, K3 (Table 2).

    The elliptic damping is a constant b = 0.34 kN (Fig. 5-1's P4 at 0.3 mm, 2 Hz): a model file's elliptic_damping
    takes a number, not the spec's b ~ A table.
    """
    from rubber_rig.models.seed004 import seed004_pad_spec
    k_odd = seed004_pad_spec()['k_odd']
    return {'name': 'seed004_pad', 'elements': [
        {'type': 'operating_point_spring', 'k_odd': [k if np.isscalar(k) else [list(r) for r in k] for k in k_odd],
         'frequency': 2.0, 'amplitude': 0.3e-3, 'reversal_threshold': 2e-6},
        {'type': 'elliptic_damping', 'b': '0.34 kN', 'reversal_threshold': 2e-6}]}


HIGH_BAND_PROGRAM = {'name': 'high_band', 'defaults': {'taper_cycles': 2, 'cycles': 30, 'mean': 0.0},
                     'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.2 mm', '0.4 mm'],
                                 'frequency': ['25 Hz', '35 Hz', '45 Hz', '60 Hz']}]}
NARROW_PROGRAM = {'name': 'narrow_band', 'defaults': {'taper_cycles': 1, 'cycles': 30, 'mean': 0.0},
                  'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.25 mm', '0.6 mm'],
                              'frequency': ['15 Hz', '22 Hz', '30 Hz', '40 Hz']}]}
CUBIC = {'type': 'polynomial_spring', 'k3': '6e11 N/m^3'}
MAXWELL = {'type': 'maxwell', 'k': '2 kN/mm', 'c': '5 kNs/m'}     # a viscous branch the seed-000 model lacks
DASHPOT = {'type': 'dashpot', 'c': '2 kNs/m'}                     # a plain viscous term seed 000's model lacks
FAST_MAXWELL = {'type': 'maxwell', 'k': '3 kN/mm', 'c': '3 kNs/m'}   # relaxes at 160 Hz: above a 15-40 Hz band


def post_heating(run, seed):
    """The specimen softens by 4 % over the test (every force scaled down linearly in time)."""
    run.force = run.force * (1.0 - 0.04 * np.arange(run.force.size) / run.force.size)
    return run


def post_spikes(run, seed):
    """Spikes of +-800 N (40 noise sigmas) on 0.05 % of the force samples."""
    rng = np.random.default_rng(1000 + seed)
    hit = rng.choice(run.force.size, size=max(run.force.size // 2000, 3), replace=False)
    run.force = run.force.copy()
    run.force[hit] += rng.choice([-800.0, 800.0], hit.size)
    return run


def post_clipped(run, seed):
    """A load cell that clips at 85 % of the largest force it saw."""
    limit = 0.85 * float(np.max(np.abs(run.force)))
    run.force = np.clip(run.force, -limit, limit)
    return run


def post_wrong_label(run, seed):
    """The metadata says 20 degC; the record (and its temperature channel) is at 0 degC."""
    from rubber_rig.fitting.data import with_temperature
    run.temperature_metadata = 20.0
    return with_temperature(run)


def post_blue_noise(run, seed):
    """The load cell's noise is the difference of white noise (15 N): blue, so any white-noise estimator (third
    differences) reads it 1.3 x high (its variance 1.75 x).
    """
    e = np.random.default_rng(2000 + seed).normal(0.0, 15.0, run.force.size + 1)
    run.force = run.force + np.diff(e)
    return run


def _tanh_friction():
    """Seed 000's viscoelastic part with a velocity-driven friction law (seed 002 Eq. 46) instead of Berg's."""
    d = _seed000('20C')
    d['elements'][1] = {'type': 'tanh_coulomb', 'f_c': '4.57 kN', 'a': '2000 s/m'}
    return d


SHORT_PROGRAM = {'name': 'short_blocks', 'defaults': {'taper_cycles': 1, 'cycles': 3, 'mean': 0.0},
                 'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.5 mm', '1 mm'],
                             'frequency': ['0.5 Hz', '1 Hz', '2 Hz', '4 Hz', '6 Hz', '8 Hz', '10 Hz', '14 Hz']}]}
UNDECLARED = {'declare': False}   # the lab states no load-cell calibration (else: exact, --record-calibration)
# where a case declares the load cell at fit time, the lab declares its (exact) displacement transducer and
# temperature sensor too; else the fit rightly warns that their contributions are missing
EXACT_OTHERS = {'displacement_gain_u': 0.0, 'temperature_u': 0.0}
# name -> (specimen (mapping or callable), program, simulate options, [(fit label, model, fit options)], true label)
CASES = {
    **{f'seed000_{t}': (lambda t=t: _seed000(t), GRID, {},
                        [('zener_berg', 'zener_berg', {}), ('zener_berg_cubic', 'zener_berg_cubic', {})],
                        'zener_berg') for t in ('20C', '0C', 'm20C', 'm40C')},
    'cubic': (lambda: _seed000('20C', [CUBIC]), GRID, {},
              [('zener_berg_cubic', 'zener_berg_cubic', {}), ('zener_berg', 'zener_berg', {})], 'zener_berg_cubic'),
    # seed 003's two-order fractional model has more parameters than a 1-50 Hz grid pins down: with its
    # orders free the fit must say so; with the orders fixed (at the truth) it is identifiable
    'seed003': (lambda: _named('seed003'), SEED003_PROGRAM, {},
                [('seed003, orders fixed', _fixed_orders, {}), ('seed003, all free', 'seed003', {}),
                 ('zener_berg', 'zener_berg', {})], 'seed003, orders fixed'),
    'pad': (_pad_specimen, PAD_PROGRAM, {}, [('per_block', 'per_block', {}), ('zener_berg', 'zener_berg', {})],
            'per_block'),
    'late_0.2ms': (lambda: _seed000('20C'), GRID, {'load_cell_delay': '0.2ms', **UNDECLARED},
                   [('zener_berg', 'zener_berg', {}),
                    ('zener_berg, --estimate-delay', 'zener_berg', {'estimate_delay': True})], 'zener_berg'),
    'late_0.2ms_declared': (lambda: _seed000('20C'), GRID, {'load_cell_delay': '0.2ms'},
                            [('zener_berg', 'zener_berg', {})], 'zener_berg'),
    'gain_+1%': (lambda: _seed000('20C'), GRID, {'load_cell_gain': '1.01', **UNDECLARED},
                 [('zener_berg, no calibration', 'zener_berg', {}),
                  ('zener_berg, gain 1 +- 1 % declared', 'zener_berg', {'load_cell_gain_u': 0.01,
                                                                        'load_cell_delay_u': 0.0, **EXACT_OTHERS}),
                  ('zener_berg, --load-cell-gain 1.01', 'zener_berg', {'load_cell_gain': 1.01})], None),
    'gain_0.97': (lambda: _seed000('20C'), GRID, {'load_cell_gain': '0.97', **UNDECLARED},
                  [('zener_berg, no calibration', 'zener_berg', {}),
                   ('zener_berg, gain 1 +- 3 % declared', 'zener_berg', {'load_cell_gain_u': 0.03,
                                                                         'load_cell_delay_u': 0.0,
                                                                         **EXACT_OTHERS})], None),
    'maxwell': (lambda: _seed000('20C', [MAXWELL]), GRID, {},
                [('zener_berg + maxwell', lambda: _seed000('20C', [MAXWELL]), {}),
                 ('zener_berg', 'zener_berg', {}), ('zener_berg, --estimate-delay', 'zener_berg',
                                                    {'estimate_delay': True})], 'zener_berg + maxwell'),
    'short_blocks': (lambda: _seed000('20C'), SHORT_PROGRAM, {},
                     [('zener_berg, --settle-cycles 1', 'zener_berg', {'settle_cycles': 1})], None),
    'dashpot': (lambda: _seed000('20C', [DASHPOT]), GRID, {},
                [('zener_berg + dashpot', lambda: _seed000('20C', [DASHPOT]), {}), ('zener_berg', 'zener_berg', {})],
                'zener_berg + dashpot'),
    'friction_tanh': (_tanh_friction, GRID, {}, [('zener_berg', 'zener_berg', {})], None),
    'offset_200N': (lambda: _seed000('20C'), GRID, {'force_offset': '200N'},
                    [('zener_berg', 'zener_berg', {})], 'zener_berg'),
    'drift_2N_per_s': (lambda: _seed000('20C'), GRID, {'force_drift': '2N/s'},
                       [('zener_berg', 'zener_berg', {})], 'zener_berg'),
    'drift_20N_per_s': (lambda: _seed000('20C'), GRID, {'force_drift': '20N/s'},
                        [('zener_berg', 'zener_berg', {})], None),
    'low_band': (lambda: _seed000('20C', [CUBIC]), LOWBAND_PROGRAM, {'load_cell_delay': '0.2ms', **UNDECLARED},
                 [('zener_berg', 'zener_berg', {}), ('zener_berg_cubic', 'zener_berg_cubic', {})], None),
    # issue 38: the measured band, the noise, the temperature and the named diagnoses
    'high_band_0C': (lambda: _seed000('0C'), HIGH_BAND_PROGRAM, {}, [('zener_berg', 'zener_berg', {})],
                     'zener_berg'),
    'narrow_fast_maxwell': (lambda: _seed000('20C', [FAST_MAXWELL]), NARROW_PROGRAM, {},
                            [('zener_berg', 'zener_berg', {})], None),
    'heating_4%': (lambda: _seed000('20C'), GRID, {'post': post_heating}, [('zener_berg', 'zener_berg', {})], None),
    'spikes': (lambda: _seed000('20C'), GRID, {'post': post_spikes}, [('zener_berg', 'zener_berg', {})], None),
    'clipped_85%': (lambda: _seed000('20C'), GRID, {'post': post_clipped}, [('zener_berg', 'zener_berg', {})],
                    None),
    'label_20C_at_0C': (lambda: _seed000('0C'), GRID, {'post': post_wrong_label},
                        [('zener_berg', 'zener_berg', {})], None),
    'blue_noise': (lambda: _seed000('20C'), GRID, {'post': post_blue_noise, 'force_noise': '1N'},
                   [('zener_berg', 'zener_berg', {})], None),
}


# what each fit must show (the targets): None = clean (every parameter covered in >= 90 % of the seeds,
# no warning); a code = that warning in >= 95 % of the seeds. The true structure of each case is clean unless
# listed; fits not listed (and not the true one) are shown without a target (e.g. seed 000 fitted with an
# unneeded cubic term: not wrong, and its "k3 consistent with zero" share is in the codes column).
EXPECT = {
    # at -40 degC the 0.5-14 Hz grid reaches only ~80 % of the way to K_inf (tau 15 ms, alpha 0.86): the rest is
    # the Zener shape, and the true model's fit says so (issue 38, the measured band as a limit)
    'seed000_m40C': {'zener_berg': 'extrapolation'},
    # the Maxwell branch relaxes at 64 Hz, above the 14 Hz grid: K_inf and the branch's k are partly out-of-band
    'maxwell': {'zener_berg + maxwell': 'extrapolation', 'zener_berg': 'misfit', 'zener_berg, --estimate-delay':
                'misfit'},
    'cubic': {'zener_berg': 'misfit'},
    'seed003': {'seed003, all free': 'identifiability', 'zener_berg': 'misfit'},
    'pad': {'zener_berg': 'misfit'},
    'late_0.2ms': {'zener_berg': 'calibration_disagrees', 'zener_berg, --estimate-delay': 'delay'},
    'gain_+1%': {'zener_berg, no calibration': 'calibration_undeclared', 'zener_berg, gain 1 +- 1 % declared': None,
                 'zener_berg, --load-cell-gain 1.01': 'calibration_undeclared'},
    'gain_0.97': {'zener_berg, no calibration': 'calibration_undeclared',
                  'zener_berg, gain 1 +- 3 % declared': None},
    'short_blocks': {'zener_berg, --settle-cycles 1': 'short_blocks'},
    'dashpot': {'zener_berg': 'misfit'},
    'friction_tanh': {'zener_berg': 'misfit'},
    'drift_20N_per_s': {'zener_berg': 'misfit'},
    'low_band': {'zener_berg': 'misfit', 'zener_berg_cubic': 'calibration_undeclared'},
    # on 25-60 Hz alone K_inf and the friction trade off (+-12 %): the fit says so, and K0's share beyond the band
    # then stays within its own wide interval (no extrapolation warning; measured: 4 of 4 seeds)
    'high_band_0C': {'zener_berg': 'identifiability'},
    'narrow_fast_maxwell': {'zener_berg': 'extrapolation'},
    'heating_4%': {'zener_berg': 'non_stationary'},
    'spikes': {'zener_berg': 'outliers'},
    'clipped_85%': {'zener_berg': 'saturation'},
    'label_20C_at_0C': {'zener_berg': 'temperature_disagrees'},
    'blue_noise': {'zener_berg': 'noise_overstated'},
}


def expected(case, fit, true):
    """(judged?, code or None) of a fit: see EXPECT."""
    if fit in EXPECT.get(case, {}):
        return True, EXPECT[case][fit]
    return (True, None) if true else (False, None)


def _keep(path: Path, text: str) -> None:
    """Write ``text`` to ``path``; if it held something else, the recordings beside it are stale: remove them."""
    if path.exists() and path.read_text() == text:
        return
    for old in path.parent.glob('*.mcap'):
        old.unlink(missing_ok=True)
    tmp = path.with_suffix(f'.{os.getpid()}.tmp')
    tmp.write_text(text)
    os.replace(tmp, path)        # atomic: a second worker reads the old or the new file, never half of one


def simulate(case, seed, out_dir: Path) -> Path:
    from rubber_rig.cli.main import main
    specimen, program, sim_opts, _, _ = CASES[case]
    d = out_dir / case
    d.mkdir(parents=True, exist_ok=True)
    model_file = d / 'specimen.yaml'
    _keep(model_file, yaml.safe_dump(specimen() if callable(specimen) else specimen, sort_keys=False))
    if isinstance(program, dict):
        prog_file = d / 'program.yaml'
        _keep(prog_file, yaml.safe_dump(program, sort_keys=False))
        program = str(prog_file)
    declared = sim_opts.get('declare', True)
    path = d / f'seed{seed:02d}{"_declared" if declared else ""}.mcap'
    if not path.exists():
        args = ['simulate', '--model', str(model_file), '--program', program, '-o', str(path), '--seed', str(seed),
                '--force-noise', sim_opts.get('force_noise', '20N')] + (['--record-calibration'] if declared else [])
        if 'load_cell_delay' in sim_opts:
            args += ['--load-cell-delay', sim_opts['load_cell_delay']]
        if 'load_cell_gain' in sim_opts:
            args += ['--load-cell-gain', sim_opts['load_cell_gain']]
        for key in ('force_offset', 'force_drift'):
            if key in sim_opts:
                args += ['--' + key.replace('_', '-'), sim_opts[key]]
        with contextlib.redirect_stdout(io.StringIO()):
            rc = main(args)
        if rc != 0:
            raise RuntimeError(f'simulate {case} seed {seed} failed ({rc})')
    return path


def per_block_rows(run):
    """Per-block seed-004 identification vs the specimen's operating-point coefficients."""
    from rubber_rig.fitting.blocktrend import fit_blocks
    from rubber_rig.fitting.identification import split_runs
    from rubber_rig.models.trend import trend_value
    groups, _ = split_runs([run])
    items = [(r, b) for g in groups.values() for r, b, _ in g]
    rows = fit_blocks(items)
    spec = run.metadata['specimen']['elements']
    k1, k3 = spec[0]['k_odd']
    b_true = float(spec[1]['b'])
    out = []
    for r in rows:
        truth = {'K1': float(trend_value(k1, r['frequency'], r['amplitude'])),
                 'K3': float(trend_value(k3, r['frequency'], r['amplitude'])), 'b': b_true}
        for k, tv in truth.items():
            out.append((k, r[k] / tv - 1, abs(r[k] - tv) <= 1.96 * r['sigma'][k], r['chi2_per_dof']))
    return out


def fit_task(task):
    case, seed, out_dir = task
    from rubber_rig.fitting.data import load_run
    from rubber_rig.fitting.identification import compare_models, fit_model
    t0 = time.perf_counter()
    path = simulate(case, seed, Path(out_dir))
    sim_s = time.perf_counter() - t0
    run = load_run(path)
    _, _, sim_opts, fits, true_label = CASES[case]
    if 'post' in sim_opts:
        run = sim_opts['post'](run, seed)
    results, by_model = [], {}
    for label, model, opts in fits:
        t1, c1 = time.perf_counter(), time.process_time()
        if model == 'per_block':
            rows = per_block_rows(run)
            cover = {f'{k}#{i}': c for i, (k, _, c, _) in enumerate(rows)}
            chi = float(np.median([c2 for *_, c2 in rows]))
            results.append({'case': case, 'seed': seed, 'fit': label, 'true': label == true_label,
                            'errors': {}, 'max_abs_error': float(max(abs(e) for _, e, _, _ in rows)),
                            'covered': cover, 'chi2_per_dof': chi, 'warnings': [], 'fit_s': time.perf_counter() - t1,
                            'sim_s': sim_s})
            continue
        fitted, _ = fit_model([run], model() if callable(model) else model, **opts)
        f = fitted[0]
        by_model[label] = fitted
        d = f.as_dict()
        errors = d.get('errors', {})
        covered = d.get('covered', {})
        z = {k: abs(f.parameters[k] - f.truth[k]) / f.uncertainty[k]['sigma']
             for k in covered if f.uncertainty[k]['sigma'] > 0} if f.truth else {}
        results.append({'case': case, 'seed': seed, 'fit': label, 'true': label == true_label,
                        'errors': errors, 'max_abs_error': max((abs(v) for v in errors.values()), default=math.nan),
                        'covered': covered, 'chi2_per_dof': f.chi2_per_dof, 'warnings': [str(w) for w in f.warnings],
                        'codes': sorted({w.code for w in f.warnings}), 'max_z': max(z.values(), default=0.0),
                        'delay_ms': 1e3 * (f.parameters.get('load_cell_delay') or 0.0),
                        'fit_s': time.perf_counter() - t1, 'cpu_s': time.process_time() - c1, 'sim_s': sim_s})
    if len(by_model) > 1 and true_label in by_model:
        comp = compare_models(by_model)[0]
        for r in results:
            r['aic_true'] = comp['selected_aic'] == true_label
            r['bic_true'] = comp['selected_bic'] == true_label
    return results


def summarise(rows):
    table = []
    keys = []
    for r in rows:
        if (r['case'], r['fit']) not in keys:
            keys.append((r['case'], r['fit']))
    for case, fit in keys:
        rs = [r for r in rows if r['case'] == case and r['fit'] == fit]
        names = sorted({k for r in rs for k in r['errors']})
        med = {k: float(np.median([abs(r['errors'][k]) for r in rs if k in r['errors']])) for k in names}
        worst_param = max(med, key=med.get) if med else ''
        cover_all = [c for r in rs for c in r['covered'].values()]
        params = sorted({k.split('#')[0] for r in rs for k in r['covered']})
        cov_by_param = {p: float(np.mean([c for r in rs for k, c in r['covered'].items() if k.split('#')[0] == p]))
                        for p in params}
        table.append({
            'case': case, 'fit': fit, 'true_model': rs[0]['true'], 'seeds': len(rs),
            'worst_median_error': (worst_param, med.get(worst_param, math.nan)) if med else
            ('per block', float(np.median([r['max_abs_error'] for r in rs]))) if fit == 'per_block' else
            ('- (no truth in this structure)', math.nan),
            'coverage_all': float(np.mean(cover_all)) if cover_all else math.nan,
            'coverage_worst_param': (min(cov_by_param, key=cov_by_param.get), min(cov_by_param.values()))
            if cov_by_param else ('', math.nan),
            'chi2_per_dof': float(np.median([r['chi2_per_dof'] for r in rs])),
            'warned': float(np.mean([bool(r['warnings']) for r in rs])),
            'aic_true': float(np.mean([r['aic_true'] for r in rs])) if 'aic_true' in rs[0] else math.nan,
            'bic_true': float(np.mean([r['bic_true'] for r in rs])) if 'bic_true' in rs[0] else math.nan,
            'fit_s_max': float(max(r['fit_s'] for r in rs)),
            'cpu_s_max': float(max(r.get('cpu_s', math.nan) for r in rs)),
            'example_warning': next((r['warnings'][0] for r in rs if r['warnings']), ''),
            # each warning code: the share of seeds that carry it
            'codes': {c: float(np.mean([c in r.get('codes', []) for r in rs]))
                      for c in sorted({c for r in rs for c in r.get('codes', [])})},
            # the worst outcome: a truth outside the 95 % interval (or > 3 sigma away) and not one warning
            'silent_misses': int(sum(1 for r in rs if not r['warnings'] and not all(r['covered'].values()))),
            'silent_3sigma': int(sum(1 for r in rs if not r['warnings'] and r.get('max_z', 0.0) > 3)),
        })
        judged, code = expected(case, fit, rs[0]['true'])
        t = table[-1]
        if not judged:
            t['target'] = ''
        elif code is None:
            cp, cv = t['coverage_worst_param']
            covered = cv >= 0.9 or fit == 'per_block'
            n = len(rs)
            ok = covered and t['warned'] == 0 and t['silent_3sigma'] == 0
            t['target'] = f'clean: {"met" if ok else "MISSED"}'
            if not covered:
                # with 10 seeds a true 95 % interval shows <= 8/10 in 9 % of the parameters: say how likely
                k = round(cv * n)
                t['target'] += f' ({cp} {k}/{n}; P = {binom.cdf(k, n, 0.95):.2g} for a true 95 % interval)'
            if t['warned']:
                t['target'] += f' (warned in {round(t["warned"] * n)}/{n}: {", ".join(t["codes"])})'
            if t['silent_3sigma']:
                t['target'] += f' ({t["silent_3sigma"]}/{n} seeds > 3 sigma from the truth without a warning)'
        else:
            share = t['codes'].get(code, 0.0)
            t['target'] = f'{code} in {100 * share:.0f} %: {"met" if share >= 0.95 else "MISSED"}'
    return table


def print_table(table, out=sys.stdout):
    print('| case | fitted model | true? | seeds | worst median abs error | 95 % coverage all / worst param | '
          'chi2/dof (median) | seeds warned | warning codes (share of seeds) | uncovered truth without a warning '
          '(> 3 sigma) | target | AIC / BIC pick true | slowest fit (wall / CPU) |', file=out)
    print('|---|---|---|---|---|---|---|---|---|---|---|---|---|', file=out)
    for t in table:
        wp, we = t['worst_median_error']
        cp, cv = t['coverage_worst_param']
        pick = '' if math.isnan(t['aic_true']) else f'{100 * t["aic_true"]:.0f} % / {100 * t["bic_true"]:.0f} %'
        print(f'| {t["case"]} | {t["fit"]} | {"yes" if t["true_model"] else "no"} | {t["seeds"]} | '
              f'{wp} {100 * we:.2f} % | {100 * t["coverage_all"]:.0f} % / {cp} {100 * cv:.0f} % | '
              f'{t["chi2_per_dof"]:.3g} | {100 * t["warned"]:.0f} % | '
              f'{", ".join(f"{c} {100 * v:.0f} %" for c, v in t["codes"].items()) or "-"} | '
              f'{t["silent_misses"]} ({t["silent_3sigma"]}) | {t.get("target", "")} | {pick} | '
              f'{t["fit_s_max"]:.1f} s / {t.get("cpu_s_max", math.nan):.1f} s |', file=out)
    print(file=out)
    for t in table:
        if t['example_warning']:
            print(f'- {t["case"]} / {t["fit"]}: "{t["example_warning"]}"', file=out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, default=20)
    ap.add_argument('--cases', default='all', help=f'comma-separated subset of {", ".join(CASES)}')
    ap.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument('--dir', default='/tmp/rubber_rig_bench_identification', help='recordings (reused)')
    ap.add_argument('--json', default=None, help='also write all rows to this JSON file')
    ap.add_argument('--markdown', default=None, help='also write the table to this Markdown file (the README '
                    'links docs/benchmarks/identification.md)')
    ap.add_argument('--first-seed', type=int, default=0, help='seeds first-seed .. first-seed + seeds - 1')
    ap.add_argument('--from-json', default=None, nargs='+', help='no run: summarise the rows of earlier --json '
                    'files together (e.g. seeds 0-9 and a second run of seeds 10-19)')
    args = ap.parse_args(argv)
    if args.from_json:
        runs = [json.loads(Path(p).read_text()) for p in args.from_json]
        rows = [r for d in runs for r in d['rows']]
        header = '; '.join(d.get('header', p) for d, p in zip(runs, args.from_json, strict=True))
        return report(summarise(rows), header, args.markdown)
    cases = list(CASES) if args.cases == 'all' else args.cases.split(',')
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        ap.error(f'unknown case(s) {unknown}; known: {", ".join(CASES)}')
    tasks = [(c, s, args.dir) for c in cases for s in range(args.first_seed, args.first_seed + args.seeds)]
    t0 = time.perf_counter()
    with Pool(args.jobs) as pool:
        rows = [r for rs in pool.imap(fit_task, tasks) for r in rs]
    table = summarise(rows)
    header = (f'identification benchmark: {args.seeds} noise seeds per case ({", ".join(cases)}; seeds '
              f'{args.first_seed}-{args.first_seed + args.seeds - 1}), 20 N load-cell noise, 1 kHz, '
              f'{time.perf_counter() - t0:.0f} s wall, {args.jobs} jobs')
    if args.json:
        Path(args.json).write_text(json.dumps({'rows': rows, 'table': table, 'header': header}, indent=1,
                                              default=str))
    return report(table, header, args.markdown)


def report(table, header, markdown=None) -> int:
    """Print the table (and write it to ``markdown``); exit status 1 when a target was missed."""
    print(header)
    print_table(table)
    if markdown:
        buf = io.StringIO()
        print(f'# Identification benchmark\n\nGenerated by `benchmarks/bench_identification.py` (its docstring says '
              f'what each case is). {header}.\n', file=buf)
        print_table(table, buf)
        Path(markdown).parent.mkdir(parents=True, exist_ok=True)
        Path(markdown).write_text(buf.getvalue())
    missed = [f'{t["case"]} / {t["fit"]}' for t in table if 'MISSED' in t.get('target', '')]
    if missed:
        print(f'targets missed: {"; ".join(missed)}')
    return 1 if missed else 0


if __name__ == '__main__':
    sys.exit(main())
