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


"""`rubber-rig simulate` and the simulated load cell's delay and gain.

Recordings are read back with independent readers (the mcap library with mcap_ros2's decoder); the delay
line's per-tick and block paths of the simulated controller give the very same samples.
"""
import json

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from scipy.optimize import minimize_scalar

from rubber_rig.cli.main import main as cli
from rubber_rig.excitation import Program
from rubber_rig.rig import RigConfig
from rubber_rig.rig.config import ConfigError, SimOptions
from rubber_rig.rig.sim.controller import SimController
from rubber_rig.rig.sim.plant import DelayLine
from rubber_rig.session import run_program
from rubber_rig.settings import settings_of

from support.rig import FAST, expected_plant

MODEL = """\
name: sarj_cubic
temperature: 23 degC
elements:
  - {type: fractional_zener, k0: 12.29 kN/mm, k_inf: 14.01 kN/mm, tau: 0.043 s, alpha: 0.659}
  - {type: berg, x2: 1.41 mm, f_fmax: 4.57 kN}
  - {type: polynomial_spring, k3: 6e11 N/m^3}
"""
PROGRAM = """\
name: short
blocks:
  - {waveform: sine, frequency: 4 Hz, amplitude: 0.5 mm, cycles: 8, taper_cycles: 1}
  - {waveform: sine, frequency: 8 Hz, amplitude: 0.3 mm, cycles: 8, taper_cycles: 1}
"""
N_SAMPLES = 3750          # the program at 1 kHz: 2 s + 1 s of sines plus their tapers
SAMPLES = '/rubber_rig/samples'


@pytest.fixture(scope='module')
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp('simulate')
    (d / 'model.yaml').write_text(MODEL)
    (d / 'program.yaml').write_text(PROGRAM)
    return d


def simulate(files, out, *extra):
    return cli(['simulate', '--model', str(files / 'model.yaml'), '--program', str(files / 'program.yaml'),
                '-o', str(files / out), *extra])


def read(path):
    """(samples {sequence, displacement, force, setpoint, temperature}, rubber_rig metadata), read by the mcap
    library and mcap_ros2's decoder."""
    out = {k: [] for k in ('sequence', 'displacement', 'force', 'setpoint', 'temperature')}
    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, _, _, msg in reader.iter_decoded_messages(topics=[SAMPLES]):
            n = len(msg.force)
            out['sequence'].append(msg.first_sequence + np.arange(n))
            for k in ('displacement', 'force', 'setpoint'):
                out[k].append(np.asarray(getattr(msg, k), float))
            out['temperature'].append(np.full(n, msg.temperature))
        f.seek(0)
        records = {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}
    meta = records['rubber_rig']
    for key in meta.pop('_json_keys', '').split(','):
        if key:
            meta[key] = json.loads(meta[key])
    return {k: np.concatenate(v) for k, v in out.items()}, meta


def lag(reference, delayed, fs=1000.0):
    """The delay [s] that best maps `reference` onto `delayed` (least squares, linear interpolation)."""
    t = np.arange(reference.size) / fs
    inner = slice(200, -200)
    cost = lambda tau: np.mean((delayed[inner] - np.interp(t[inner] - tau, t, reference)) ** 2)  # noqa: E731
    return minimize_scalar(cost, bounds=(-1e-3, 3e-3), method='bounded', options={'xatol': 1e-8}).x


@pytest.fixture(scope='module')
def quiet(files):
    """A noise-free run without load-cell imperfections: the reference."""
    assert simulate(files, 'quiet.mcap', '--force-noise', '0', '--displacement-noise', '0', '--seed', '7') == 0
    return read(files / 'quiet.mcap')[0]


def test_simulate_writes_a_bench_format_recording_with_the_model_inline(files, capsys):
    assert simulate(files, 'run.mcap', '--load-cell-delay', '0.2ms', '--load-cell-gain', '1.02',
                    '--force-offset', '15N', '--seed', '3') == 0
    line = capsys.readouterr().out.strip()
    assert len(line.splitlines()) == 1 and f'{N_SAMPLES} samples' in line and '3.750 s' in line
    assert '2 blocks' in line and str(files / 'run.mcap') in line
    s, meta = read(files / 'run.mcap')
    np.testing.assert_array_equal(s['sequence'], np.arange(N_SAMPLES))
    assert np.all(np.isfinite(s['force'])) and 3e3 < np.max(np.abs(s['force'])) < 15e3
    # the truth, self-contained: the model file's mapping in SI, not a path
    spec = meta['specimen']
    assert spec['name'] == 'sarj_cubic' and [e['type'] for e in spec['elements']] == [
        'fractional_zener', 'berg', 'polynomial_spring']
    assert spec['elements'][0]['k0'] == pytest.approx(12.29e6) and spec['elements'][1]['x2'] == pytest.approx(1.41e-3)
    assert spec['elements'][2]['k3'] == pytest.approx(6e11)
    # temperature from the model file (23 degC): metadata and channel
    assert meta['temperature'] == 23.0 and s['temperature'].mean() == pytest.approx(23.0, abs=0.05)
    assert meta['source'] == 'rubber-rig simulate' and 'name: short' in meta['program']
    sim = meta['rig_config']['sim']
    assert sim['force_delay'] == pytest.approx(0.2e-3) and sim['force_gain'] == 1.02 and sim['force_offset'] == 15.0
    assert sim['force_noise'] == 2.0 and sim['seed'] == 3 and meta['rig_config']['sample_rate'] == 1000.0
    # the lab's calibration is recorded only when asked for
    assert 'load_cell_delay' not in meta['rig_config']
    assert simulate(files, 'cal.mcap', '--load-cell-delay', '1ms', '--record-calibration') == 0
    cfg = read(files / 'cal.mcap')[1]['rig_config']
    assert cfg['load_cell_delay'] == pytest.approx(1e-3) and cfg['load_cell_gain'] == 1.0
    assert RigConfig.from_dict(cfg).load_cell_delay == pytest.approx(1e-3)   # a valid rig configuration


@pytest.mark.parametrize('delay, seconds', [('1ms', 1e-3), ('0.2ms', 0.2e-3)])
def test_load_cell_delay_shifts_the_recorded_force(files, quiet, delay, seconds):
    assert simulate(files, 'delayed.mcap', '--force-noise', '0', '--displacement-noise', '0', '--seed', '7',
                    '--load-cell-delay', delay) == 0
    s = read(files / 'delayed.mcap')[0]
    np.testing.assert_array_equal(s['displacement'], quiet['displacement'])    # only the load cell is late
    assert lag(quiet['force'], s['force']) == pytest.approx(seconds, abs=0.03e-3)
    assert lag(quiet['force'], quiet['force']) == pytest.approx(0.0, abs=0.03e-3)


def test_load_cell_gain_scales_the_recorded_force(files, quiet):
    assert simulate(files, 'gain.mcap', '--force-noise', '0', '--displacement-noise', '0', '--seed', '7',
                    '--load-cell-gain', '1.05') == 0
    s = read(files / 'gain.mcap')[0]
    np.testing.assert_allclose(s['force'], 1.05 * quiet['force'], atol=0.02)     # 0.01 N resolution
    ratio = np.dot(s['force'], quiet['force']) / np.dot(quiet['force'], quiet['force'])
    assert ratio == pytest.approx(1.05, abs=1e-6)


def test_shipped_program_and_named_model(tmp_path, capsys):
    out = tmp_path / 'pad.mcap'
    assert cli(['simulate', '--model', 'pad', '--program', 'preload_sine_grid', '--rate', '100Hz', '-o', str(out)]) == 0
    assert '22 blocks' in capsys.readouterr().out
    s, meta = read(out)
    assert s['sequence'].size > 6000 and meta['specimen']['name'] == 'pad'
    assert [e['type'] for e in meta['specimen']['elements']] == ['polynomial_spring', 'elliptic_damping']
    assert meta['temperature'] == 20.0 and meta['rig_config']['sample_rate'] == 100.0


@pytest.mark.parametrize('content, names', [
    ('elements:\n  - {type: berg, x2: 1.41 mm}\n', 'f_fmax'),
    ('elements:\n  - {type: nosuch, k: 1}\n', 'nosuch'),
    ('elements: [\n', 'not valid YAML'),
    ('name: x\n', 'elements'),
    ('elements:\n  - {type: berg, x2: 1.41 kg, f_fmax: 1 kN}\n', 'kg'),
])
def test_bad_model_file_is_refused_naming_the_file(files, tmp_path, capsys, content, names):
    bad = tmp_path / 'bad_model.yaml'
    bad.write_text(content)
    out = tmp_path / 'x.mcap'
    rc = cli(['simulate', '--model', str(bad), '--program', str(files / 'program.yaml'), '-o', str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and 'bad_model.yaml' in err and names in err and 'Traceback' not in err
    assert not out.exists()


@pytest.mark.parametrize('args, names', [
    (['--model', 'missing_model.yaml'], 'missing_model.yaml'),
    (['--model', 'no_such_model'], 'no_such_model'),
    (['--program', 'no_such_program'], 'preload_sine_grid'),          # the message lists the shipped programs
    (['--load-cell-delay', '5kg'], '--load-cell-delay'),
    (['--load-cell-delay', '0.2s'], '0 .. 0.1 s'),
    (['--load-cell-gain', '0'], '--load-cell-gain'),
    (['--rate', '5Hz'], '--rate'),
    (['--temperature=-100degC'], '--temperature'),
])
def test_bad_values_are_refused_naming_what_is_wrong(files, tmp_path, capsys, args, names):
    argv = ['simulate', *args, '-o', str(tmp_path / 'x.mcap')]
    for option, default in (('--model', files / 'model.yaml'), ('--program', files / 'program.yaml')):
        if option not in args:
            argv += [option, str(default)]
    assert cli(argv) == 2
    assert names in capsys.readouterr().err
    assert not (tmp_path / 'x.mcap').exists()


# ---- the simulated load cell -------------------------------------------------------------------------------

def test_delay_line_step_and_run_agree():
    x = np.sin(np.arange(500) * 0.07) * 1e3
    for delay in (0.0, 1.0, 0.3, 12.75):
        one, many = DelayLine(delay), DelayLine(delay)
        stepped = [one.step(v) for v in x]
        ran = np.concatenate([many.run(x[a:b]) for a, b in ((0, 1), (1, 40), (40, 41), (41, 500))])
        np.testing.assert_array_equal(ran, stepped)
        k = np.arange(x.size, dtype=float)
        np.testing.assert_allclose(ran, np.interp(k - delay, k, x), atol=1e-9)   # x[0] before the start


def test_force_delay_and_gain_same_samples_in_block_and_tick_paths(monkeypatch):
    """The controller's numpy block path and its per-sample path give the very same delayed, scaled samples,
    and those are gain x the true force of force_delay earlier."""
    prog = Program.from_yaml_text('name: b\nblocks:\n  - {waveform: sine, frequency: 12 Hz, amplitude: 0.5 mm, '
                                  'cycles: 6, taper_cycles: 1}\n')
    sim = {'force_delay': 0.0123, 'force_gain': 1.03, 'force_noise': 2.0}
    blocks = run_program(prog, dict(FAST, sim=sim))
    monkeypatch.setattr(SimController, 'MAX_BLOCK', 1)     # a block of one tick takes the per-sample path
    ticks = run_program(prog, dict(FAST, sim=sim))
    assert blocks.completed and ticks.completed
    n = prog.n_samples(1000.0)
    for name in ('setpoint', 'displacement', 'force'):
        np.testing.assert_array_equal(getattr(blocks, name)[:n], getattr(ticks, name)[:n])
    quiet = dict(sim, force_noise=0.0)
    r = run_program(prog, dict(FAST, sim=quiet))
    _, f = expected_plant(r, SimOptions(**quiet))
    k = np.arange(f.size, dtype=float)
    np.testing.assert_allclose(r.force, 1.03 * np.interp(k - 12.3, k, f), atol=0.006)


def test_load_cell_fields_are_settings_of_the_rig_driver_and_validated():
    s = {x.name: x for x in settings_of(RigConfig)}     # rig_driver declares one parameter per setting
    for name, units, default in (('sim.force_delay', 's', 0.0), ('sim.force_gain', '-', 1.0),
                                 ('load_cell_delay', 's', 0.0), ('load_cell_gain', '-', 1.0)):
        assert s[name].units == units and s[name].default == default and s[name].doc
        assert s[name].range[0] <= default <= s[name].range[1]
    assert s['sim.force_delay'].range == (0.0, 0.1)
    for data, field in (({'sim': {'force_delay': 0.2}}, 'sim.force_delay'), ({'sim': {'force_delay': -1e-3}},
                        'sim.force_delay'), ({'sim': {'force_gain': 0.0}}, 'sim.force_gain'),
                        ({'load_cell_gain': -1.0}, 'load_cell_gain'), ({'load_cell_delay': 0.5}, 'load_cell_delay')):
        with pytest.raises(ConfigError) as err:
            RigConfig.from_dict(data)
        assert err.value.field == field and field in str(err.value)
    pytest.importorskip('rclpy')
    from rubber_rig.nodes.rig_driver_node import RIG_SETTINGS
    assert {'sim.force_delay', 'sim.force_gain', 'load_cell_delay', 'load_cell_gain'} <= {x.name for x in RIG_SETTINGS}
