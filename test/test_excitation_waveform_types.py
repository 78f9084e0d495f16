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


"""The waveform registry and its two newer entries, haversine and random-phase multisine: generation numbers,
validation naming the field, the pre-start limit check (sampled and closed-form), and a run on the simulated
rig. No ROS."""
import math
import time
from types import SimpleNamespace

import numpy as np
import pytest

from rubber_rig.excitation import TYPES, WAVEFORMS, Program, ProgramError, ProgramRunner
from rubber_rig.excitation import limits as limits_module
from rubber_rig.excitation import waveforms as wf
from rubber_rig.excitation.detectors import blind_for, cycle_of
from rubber_rig.excitation.limits import check_program, element_force_model
from rubber_rig.excitation.waveform_types import MAX_MULTISINE_HARMONIC, multisine_harmonics
from rubber_rig.models import build_model, load_parameter_set
from rubber_rig.online.summary import BlockTable
from rubber_rig.safety import LimitError, Limits
from rubber_rig.session import run_program

FS = 1000.0


def program(*blocks: str) -> Program:
    return Program.from_yaml_text('name: t\nblocks:\n' + ''.join(f'  - {b}\n' for b in blocks))


def test_the_registry_has_one_entry_per_waveform_and_every_alias_points_at_one():
    assert WAVEFORMS == ('sine', 'triangle', 'square', 'sweep_lin', 'sweep_log', 'hold', 'ramp', 'haversine',
                         'multisine')
    for name, kind in TYPES.items():
        assert kind.name == name and kind.fields
        assert (kind.shape is not None) == kind.oscillating
    assert program('{waveform: trapezoid, frequency: 1 Hz, rate: 10 mm/s, amplitude: 1 mm, cycles: 1}'
                   ).blocks[0].waveform == 'square'


def test_a_field_the_waveform_does_not_use_is_refused_naming_it():
    with pytest.raises(ProgramError, match="block 0 'h': field 'rate': not used by waveform 'haversine'"):
        program('{name: h, waveform: haversine, frequency: 1 Hz, rate: 1 mm/s, amplitude: 1 mm, cycles: 1}')
    with pytest.raises(ProgramError, match="field 'seed': not used by waveform 'sine'"):
        program('{waveform: sine, frequency: 1 Hz, amplitude: 1 mm, cycles: 1, seed: 3}')


# ---- haversine
def test_haversine_is_one_sided_pulses_from_the_mean():
    """x = mean + A (1 - cos(2 pi f t)) / 2 at full amplitude: from the mean up to mean + A, the taper scaling
    the pulse height; starts and ends at the mean with zero velocity."""
    p = program('{waveform: ramp, target: 0.5 mm, duration: 1 s}',
                '{name: h, waveform: haversine, frequency: 5 Hz, amplitude: 1 mm, cycles: 4, taper_cycles: 1}')
    blk = p.blocks[1]
    assert blk.seconds() == pytest.approx(1.2) and blk.n_samples(FS) == 1200
    t = np.arange(1200) / FS
    x = blk.evaluate(t)
    steady = (t >= 0.2) & (t < 1.0)
    assert np.allclose(x[steady], 0.5e-3 + 1e-3 * (1 - np.cos(2 * np.pi * 5 * t[steady])) / 2, atol=1e-15)
    assert x.min() == pytest.approx(0.5e-3, abs=1e-15) and x.max() == pytest.approx(1.5e-3, rel=1e-12)
    assert x[0] == pytest.approx(0.5e-3) and blk.end_level == 0.5e-3
    # peak velocity pi f A, never exceeded by a sample step (tapers included)
    assert float(np.max(np.abs(np.diff(x)))) * FS == pytest.approx(math.pi * 5 * 1e-3, rel=1e-3)
    assert float(np.max(np.abs(np.diff(x)))) * FS <= math.pi * 5 * 1e-3
    assert TYPES['haversine'].fit_cycle(t[200:400] * 5, x[200:400]) == pytest.approx((1e-3, 0.5e-3), rel=1e-9)


def test_haversine_over_a_limit_is_refused_before_start_naming_the_limit():
    p = program('{name: pulse, waveform: haversine, frequency: 8 Hz, amplitude: 2 mm, cycles: 10}')
    check_program(Limits(displacement_min=-0.1e-3, displacement_max=2.1e-3), p, FS)   # one-sided: 0..2 mm
    with pytest.raises(LimitError, match=r"block 0 'pulse'.*displacement 0\.\.0\.0019\d* m outside the displacement"):
        check_program(Limits(displacement_max=1.9e-3), p, FS)
    v = math.pi * 8 * 2e-3                                             # 50.3 mm/s
    with pytest.raises(LimitError, match="block 0 'pulse'.*velocity_max"):
        check_program(Limits(velocity_max=0.99 * v), p, FS)


# ---- multisine
MS = ('{name: m, waveform: multisine, frequency: 0.5 Hz, f_start: 1 Hz, f_end: 20 Hz, amplitude: 1 mm, cycles: 3, '
      'seed: 3}')


def test_multisine_has_equal_lines_at_the_multiples_of_its_spacing_and_peak_amplitude():
    blk = program(MS).blocks[0]
    assert multisine_harmonics(blk) == (2, 40) and blk.seconds() == pytest.approx(10.0)
    t = np.arange(blk.n_samples(FS)) / FS
    x = blk.evaluate(t)
    period = x[2000:4000]                                            # the first full-amplitude period (2 s)
    assert np.allclose(period, x[4000:6000], atol=1e-15)             # it repeats every 1 / 0.5 Hz
    spectrum = np.abs(np.fft.rfft(period)) / period.size * 2          # bin k = k x 0.5 Hz
    lines = spectrum[2:41]
    assert np.allclose(lines, lines[0], rtol=1e-9)                   # 39 equal lines, 1..20 Hz
    assert np.max(np.delete(spectrum, np.arange(2, 41))) < 1e-12 * lines[0]
    # amplitude = peak displacement from the mean: the sampled peak is within the registry's bound
    peak, slope, _ = wf.multisine_lines(2, 40, 3)[3]
    assert 0.995e-3 < np.max(np.abs(period)) <= peak * 1e-3
    assert float(np.max(np.abs(np.diff(period)))) * FS <= slope * 0.5 * 1e-3
    assert x[0] == 0.0 and abs(x[-1]) < 1e-9
    # the seed fixes the phases: same seed same signal, another seed another one
    again = program(MS).blocks[0].evaluate(t[:3000])
    other = program(MS.replace('seed: 3', 'seed: 4')).blocks[0].evaluate(t[:3000])
    assert np.array_equal(again, x[:3000]) and not np.allclose(other, x[:3000])


@pytest.mark.parametrize('change, fld', [
    (('f_end: 20 Hz', f'f_end: {0.5 * (MAX_MULTISINE_HARMONIC + 1)} Hz'), 'f_end'),
    (('f_end: 20 Hz', 'f_end: 1.2 Hz'), 'f_end'),
    (('seed: 3', 'seed: -1'), 'seed'),
    (('seed: 3', 'seed: 2.5'), 'seed'),
    (('f_start: 1 Hz, ', ''), 'f_start'),
    (('frequency: 0.5 Hz', 'frequency: 0 Hz'), 'frequency'),
])
def test_a_bad_multisine_is_refused_naming_the_field(change, fld):
    with pytest.raises(ProgramError, match=f"block 0 'm': field '{fld}'"):
        program(MS.replace(*change))


def test_multisine_limit_check_uses_the_generated_signal():
    """The pre-start check refuses a multisine whose generated samples exceed velocity_max or the stroke,
    and passes one whose samples stay just inside."""
    p = program(MS)
    x = p.setpoints(FS)
    v, a = float(np.max(np.abs(np.diff(x)))) * FS, float(np.max(np.abs(x)))
    with pytest.raises(LimitError, match="block 0 'm'.*velocity_max"):
        check_program(Limits(velocity_max=0.999 * v), p, FS)
    with pytest.raises(LimitError, match="block 0 'm'.*displacement"):
        check_program(Limits(displacement_min=-0.999 * a, displacement_max=0.999 * a), p, FS)
    check_program(Limits(velocity_max=1.001 * v, displacement_min=-1.001 * a, displacement_max=1.001 * a), p, FS)
    with pytest.raises(ProgramError, match="field 'f_end': 20 Hz is above 10 Hz"):
        check_program(Limits(), p, 100.0)


def test_the_pre_start_check_of_a_day_long_multisine_of_4096_lines_has_a_bounded_cost():
    """A sample of a multisine costs its lines: the exact budget counts them, so the longest multisine a program
    may hold is checked from its bounds within a fraction of a second, and still refused when too fast."""
    p = program('{name: m, waveform: multisine, frequency: 0.1 Hz, f_start: 0.1 Hz, f_end: 409.6 Hz, '
                'amplitude: 0.1 mm, cycles: 8000}')
    assert p.blocks[0].seconds() > 22 * 3600 and multisine_harmonics(p.blocks[0]) == (1, 4096)
    t0 = time.process_time()
    check_program(Limits(), p, 5000.0)
    assert time.process_time() - t0 < 2.0
    with pytest.raises(LimitError, match="block 0 'm'.*velocity_max"):
        check_program(Limits(velocity_max=0.05), p, 5000.0)


WAVES = ['{name: b, waveform: haversine, frequency: 7.3 Hz, amplitude: 1.3 mm, cycles: 300, taper_cycles: 2}',
         '{name: b, waveform: multisine, frequency: 0.25 Hz, f_start: 0.5 Hz, f_end: 23 Hz, amplitude: 1.3 mm, '
         'cycles: 5, seed: 1}']


@pytest.mark.parametrize('block', WAVES)
@pytest.mark.parametrize('tapers_exact', [True, False])
def test_closed_form_bounds_agree_with_every_setpoint(block, tapers_exact, monkeypatch):
    """Beyond the exact budget the closed-form bounds refuse what the samples exceed, and accept limits 0.5 %
    (tapers sampled) or 5 % (tapers bounded) above the sampled peaks: never estimated low."""
    p = program('{name: a, waveform: hold, duration: 1 s}', block)
    x = p.setpoints(FS)
    v_peak = float(np.max(np.abs(np.diff(x)))) * FS
    lo, hi = float(np.min(x)), float(np.max(x))
    monkeypatch.setattr(limits_module, 'EXACT_SAMPLES', 1001 + (30000 if tapers_exact else 0))

    decel = 510.0       # the hardest braking a rig may declare: its stopping distance adds v^2 / (2 a)

    def limits(**kw):
        return Limits(**{'deceleration_max': decel, 'velocity_max': 1.0, **kw})
    with pytest.raises(LimitError, match="block 1 'b'.*velocity"):
        check_program(limits(velocity_max=v_peak * 0.999), p, FS)
    with pytest.raises(LimitError, match="block 1 'b'.*displacement"):
        check_program(limits(displacement_min=lo - 1e-6, displacement_max=hi * 0.999), p, FS)
    margin = 1.005 if tapers_exact else 1.05
    room = (max(abs(lo), hi) + v_peak / FS + v_peak ** 2 / (2 * decel)) * 1.005
    check_program(limits(velocity_max=v_peak * margin, displacement_min=-room, displacement_max=room), p, FS)


@pytest.mark.parametrize('block', [WAVES[0], WAVES[1].replace('cycles: 5', 'cycles: 2')])
def test_force_model_covers_a_time_domain_run_of_the_element(block):
    """The element force model's prediction of the new shapes is never below the model's peak force over the block
    run from rest and at most 3 % above it (a haversine's own mean A/2 builds up within its taper, so it is
    carried at the dynamic stiffness; its friction is taken at A, an upper bound of what a travel of A reaches)."""
    blk = program(block).blocks[0]
    fs = 5000.0
    x = blk.evaluate(np.arange(blk.n_samples(fs)) / fs)
    sim = build_model({'model': 'seed000', 'values': load_parameter_set('seed000_20C').as_dict()}, 1 / fs).run(x)
    peak = float(np.max(np.abs(sim)))
    assert peak <= element_force_model()(blk) <= 1.03 * peak


RIG = {'paced': False, 'profile': 'single'}
RUN = ('name: new_shapes\nblocks:\n'
       '  - {name: pulses, waveform: haversine, frequency: 4 Hz, amplitude: 0.5 mm, cycles: 12}\n'
       '  - {name: ms, waveform: multisine, frequency: 0.5 Hz, f_start: 1 Hz, f_end: 10 Hz, amplitude: 0.4 mm, '
       'cycles: 2, seed: 5}\n')


@pytest.mark.parametrize('control', [False, True])
def test_a_program_of_the_new_waveforms_runs_on_the_simulated_rig(control):
    p = Program.from_yaml_text(RUN)
    r = run_program(p, RIG, amplitude_control=control)
    assert r.completed, r.message
    pulses, ms = r.blocks
    assert pulses.completed and ms.completed and pulses.cycles_measured >= 6
    # a haversine's amplitude is its pulse height above the valley
    assert pulses.achieved_amplitude == pytest.approx(0.5e-3, rel=0.05 if control else 0.15)
    assert pulses.achieved_mean == pytest.approx(0.0, abs=0.05e-3)
    assert 0.3e-3 < ms.achieved_amplitude < 0.45e-3                 # half its peak-to-valley, open loop always
    assert (pulses.cycles, ms.cycles) == (12, 2)
    x = r.displacement[r.block_index == 0]                        # the pulses rise from the mean, one-sided
    assert x.min() > -0.05e-3 and 0.4e-3 < x.max() < 0.6e-3


def test_cycle_detectors_judge_haversine_pulses_but_not_multisine_periods():
    """A haversine cycle's amplitude is its peak-to-valley (twice the half range); a multisine's cycles are not
    judged (the cycle tracker's cycles are not its periods), so the detectors are neither fed nor blind there."""
    p = program('{name: h, waveform: haversine, frequency: 1 Hz, amplitude: 0.5 mm, cycles: 10}',
                '{name: m, waveform: multisine, frequency: 0.5 Hz, f_start: 1 Hz, f_end: 5 Hz, amplitude: 0.5 mm, '
                'cycles: 10}')
    r = ProgramRunner(p, FS)
    r.next_setpoints(p.n_samples(FS))
    cycle = cycle_of(r, 3000, 4000, 0.2e-3, 0.25e-3, 0.25e-3, {}, {}, 0.0, 3.0)
    assert cycle.block == 0 and cycle.amplitude == pytest.approx(0.5e-3)
    assert blind_for(r, 8000, 0, FS) == pytest.approx(8.0)
    start_m = int(p.block_starts(FS)[1])
    assert cycle_of(r, start_m + 4000, start_m + 6000, 0.2e-3, 0.25e-3, 0.0, {}, {}, 0.0, 20.0) is None
    assert blind_for(r, start_m + 20000, 0, FS) == 0.0


def _metrics(block, i, f, amplitude, peak_amplitude):
    side = SimpleNamespace(k_dyn=1e7, loss_angle=0.1, damping=0.1, c_eq=2e5, energy_harmonic=1.0, energy_loop=1.0)
    return SimpleNamespace(block_index=block, cycle_index=i, frequency=f, amplitude=amplitude,
                           peak_amplitude=peak_amplitude, mean=0.0, measured=side, model=side)


def test_the_live_table_reads_a_haversine_by_its_pulse_height_and_gives_a_multisine_no_row():
    p = program('{name: h, waveform: haversine, frequency: 2 Hz, amplitude: 0.5 mm, cycles: 8}',
                '{name: m, waveform: multisine, frequency: 0.5 Hz, f_start: 1 Hz, f_end: 5 Hz, amplitude: 0.5 mm, '
                'cycles: 4}')
    table = BlockTable(p)
    for i in range(8):                 # first harmonic 0.25 mm, half range 0.245 mm: pulses of 0.49 mm
        table.add(_metrics(0, i, 2.0, 0.25e-3, 0.245e-3))
    assert table.add(_metrics(1, 0, 3.0, 0.3e-3, 0.4e-3)) == [0]
    (row,) = table.row_list(0)
    assert row['achieved_amplitude'] == pytest.approx(0.49e-3) and row['cycles_used'] == 4
    assert table.row_list(1) == []
