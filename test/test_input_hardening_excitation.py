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

"""Bad program requests are refused with a reason naming block and field, at a bounded cost,
and the pre-start check predicts the element force per block. No rig, no ROS."""
import math

import numpy as np
import pytest

from rubber_rig.excitation import Program, ProgramError, ProgramRunner
from rubber_rig.excitation import limits as limits_module
from rubber_rig.excitation.blocks import MAX_PROGRAM_DURATION, Block
from rubber_rig.excitation.limits import check_program, element_force_model
from rubber_rig.models import build_model, load_parameter_set
from rubber_rig.safety import LimitError, Limits
from rubber_rig.settings import described

FS = 1000.0


def program(*blocks: str, head: str = '') -> Program:
    return Program.from_yaml_text(f'name: t\n{head}blocks:\n' + ''.join(f'  - {b}\n' for b in blocks))


@pytest.mark.parametrize('block, fld', [
    ('{name: a, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: .inf}', 'cycles'),
    ('{name: a, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: .nan}', 'cycles'),
    ('{name: a, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: -3}', 'cycles'),
    ('{name: a, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 1' + '0' * 400 + '}', 'cycles'),
    ('{name: a, waveform: sine, frequency: 14 Hz, amplitude: 1 mm, cycles: 100000000}', 'cycles'),
    ('{name: a, waveform: sine, frequency: 1e-9 Hz, amplitude: 1 mm, cycles: 1}', 'frequency'),
    ('{name: a, waveform: sine, frequency: .nan, amplitude: 1 mm, cycles: 1}', 'frequency'),
    ('{name: a, waveform: sine, frequency: 5 Hz, amplitude: .inf, cycles: 1}', 'amplitude'),
    ('{name: a, waveform: sine, frequency: 5 Hz, amplitude: 1e400 mm, cycles: 1}', 'amplitude'),
    ('{name: a, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 1, taper_cycles: 1e9}', 'taper_cycles'),
    ('{name: a, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 1, taper_cycles: .nan}', 'taper_cycles'),
    ('{name: a, waveform: triangle, rate: 1e-12 mm/s, amplitude: 1 mm, cycles: 1}', 'rate'),
    ('{name: a, waveform: sweep_lin, f_start: 1 Hz, f_end: 5 Hz, duration: 1e12 s, amplitude: 1 mm}', 'duration'),
    ('{name: a, waveform: sweep_log, f_start: 1 Hz, f_end: 1e-7 Hz, duration: 10 s, amplitude: 1 mm}', 'f_end'),
    ('{name: a, waveform: hold, duration: .inf}', 'duration'),
    ('{name: a, waveform: hold, duration: 100000 s}', 'duration'),
    ('{name: a, waveform: ramp, target: 1 mm, rate: 1e-12 mm/s}', 'rate'),
    ('{name: a, waveform: ramp, target: .nan, duration: 1 s}', 'target'),
])
def test_bad_numbers_are_refused_naming_block_and_field(block, fld):
    with pytest.raises(ProgramError) as exc:
        program(block)
    msg = str(exc.value)
    assert msg.startswith("block 0 'a'") and f"field '{fld}'" in msg, msg


def test_program_level_bounds():
    with pytest.raises(ProgramError, match="field 'initial_position'.*finite"):
        program('{waveform: hold, duration: 1 s}', head='initial_position: .nan\n')
    # each block fits into 24 h, together they do not: refused at the block that goes over
    with pytest.raises(ProgramError, match=r"block 1 'h2'.*longer than 86400 s"):
        program('{name: h1, waveform: hold, duration: 50000 s}', '{name: h2, waveform: hold, duration: 50000 s}')
    # a grid is counted before it is expanded (a 1000 x 1000 grid is a short text)
    values = ', '.join(str(i + 1) for i in range(1000))
    with pytest.raises(ProgramError, match="field 'frequency'.*1000 x 1000.*more than 2000"):
        program(f'{{name: g, waveform: sine, amplitude: [{values}], frequency: [{values}], cycles: 1}}')
    # the longest accepted program loads
    assert program(f'{{waveform: hold, duration: {MAX_PROGRAM_DURATION} s}}').duration(FS) == MAX_PROGRAM_DURATION


@pytest.mark.parametrize('block, fld, ok_rate', [
    ('{name: a, waveform: sine, frequency: 990 Hz, amplitude: 0.001 mm, cycles: 2}', 'frequency', 9900.0),
    ('{name: a, waveform: sine, frequency: 101 Hz, amplitude: 0.001 mm, cycles: 2}', 'frequency', 1010.0),
    ('{name: a, waveform: sweep_lin, f_start: 1 Hz, f_end: 200 Hz, duration: 1 s, amplitude: 0.001 mm}', 'f_end',
     2000.0),
    ('{name: a, waveform: triangle, rate: 1 m/s, amplitude: 1 mm, cycles: 2}', 'rate', 2500.0),   # 250 Hz
])
def test_frequencies_above_a_tenth_of_the_sample_rate_are_refused(block, fld, ok_rate):
    p = program(block)
    fast = Limits(velocity_max=10.0, deceleration_max=510.0)    # only the frequency rule can refuse these
    for check in (lambda: check_program(fast, p, FS), lambda: ProgramRunner(p, FS, fast)):
        with pytest.raises(ProgramError) as exc:
            check()
        msg = str(exc.value)
        assert msg.startswith("block 0 'a'") and f"field '{fld}'" in msg and 'sample rate of 1000 Hz' in msg, msg
    check_program(fast, p, ok_rate)                                # exactly fs/10 is accepted
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ProgramError, match='sample rate'):
            check_program(Limits(), p, bad)


@pytest.fixture
def evaluated(monkeypatch):
    """Counts the setpoints Block.evaluate generates."""
    count = [0]
    original = Block.evaluate

    def counting(self, t, *args, **kwargs):
        count[0] += np.size(t)
        return original(self, t, *args, **kwargs)
    monkeypatch.setattr(Block, 'evaluate', counting)
    return count


def test_a_24_hour_program_is_checked_without_generating_it(evaluated):
    day = MAX_PROGRAM_DURATION
    p = program(f'{{name: day, waveform: sine, frequency: 14 Hz, amplitude: 1 mm, cycles: {int(14 * day) - 4}, '
                f'taper_cycles: 2}}')
    assert p.n_samples(10000.0) == pytest.approx(day * 10000.0, abs=1)
    check_program(Limits(force_model=element_force_model()), p, 10000.0)
    assert evaluated[0] < 10000          # the two tapers, sample by sample; the rest in closed form
    with pytest.raises(LimitError, match="block 0 'day'.*velocity"):
        check_program(Limits(velocity_max=0.05), p, 10000.0)
    evaluated[0] = 0
    many = program(*[f'{{waveform: sine, frequency: 1 Hz, amplitude: 1 mm, cycles: {int(day / 100) - 4}, '
                     f'taper_cycles: 2}}'] * 100)
    check_program(Limits(), many, 1000.0)
    assert evaluated[0] <= limits_module.EXACT_SAMPLES + 100 * 4100


WAVES = ['{name: b, waveform: sine, frequency: 7.3 Hz, amplitude: 1.3 mm, cycles: 300, taper_cycles: 2}',
         '{name: b, waveform: triangle, frequency: 3.1 Hz, amplitude: 1.3 mm, cycles: 300, taper_cycles: 2}',
         '{name: b, waveform: square, frequency: 2.3 Hz, rate: 30 mm/s, amplitude: 1.3 mm, cycles: 300}',
         '{name: b, waveform: sweep_log, f_start: 1 Hz, f_end: 23 Hz, duration: 60 s, amplitude: 1.3 mm}',
         '{name: b, waveform: ramp, target: 13 mm, duration: 6 s}']   # 2.2 mm/s: above the slowest velocity_max


@pytest.mark.parametrize('block', WAVES)
@pytest.mark.parametrize('tapers_exact', [True, False])
def test_closed_form_bounds_agree_with_every_setpoint(block, tapers_exact, monkeypatch):
    """A block beyond the exact budget is refused where the sampled check refuses it, and accepted with a
    velocity limit 0.5 % (tapers sample by sample) or 5 % (tapers bounded too) above the sampled peak."""
    p = program('{name: a, waveform: hold, duration: 1 s}', block)
    x = p.setpoints(FS)
    v_peak = float(np.max(np.abs(np.diff(x)))) * FS
    x_peak = float(np.max(np.abs(x)))
    monkeypatch.setattr(limits_module, 'EXACT_SAMPLES', 1001 + (4000 if tapers_exact else 0))
    # braking at deceleration_max adds up to one sample of travel at the reversals (limits.py) and the stopping
    # distance v^2 / (2 a); at the hardest braking a rig may declare (510 m/s^2) both are small, so the
    # displacement and velocity bounds are what is compared here
    decel = 510.0
    brake = v_peak / FS + v_peak ** 2 / (2 * decel)

    def limits(**kw):
        return Limits(**{'deceleration_max': decel, 'velocity_max': 1.0, 'displacement_min': -0.02,
                         'displacement_max': 0.02, **kw})
    assert v_peak * 0.999 >= described(Limits, 'velocity_max').range[0]   # a limit a rig can be given
    with pytest.raises(LimitError, match="block 1 'b'.*velocity"):
        check_program(limits(velocity_max=v_peak * 0.999), p, FS)
    with pytest.raises(LimitError, match="block 1 'b'.*displacement"):
        check_program(limits(displacement_min=-x_peak * 0.999, displacement_max=x_peak * 0.999), p, FS)
    with pytest.raises(LimitError, match="block 1 'b'.*stiffness_estimate"):
        check_program(limits(stiffness_estimate=1e7, force_max=1e7 * x_peak * 0.999), p, FS)
    margin = 1.005 if tapers_exact or 'ramp' in block else 1.05
    room = (x_peak + brake) * 1.001
    check_program(limits(velocity_max=v_peak * margin, displacement_min=-room, displacement_max=room,
                         stiffness_estimate=1e7, force_max=1e7 * room), p, FS)


GRID = ['{name: slow, waveform: sine, frequency: 0.5 Hz, amplitude: 1 mm, cycles: 8, taper_cycles: 2}',
        '{name: fast, waveform: sine, frequency: 14 Hz, amplitude: 1 mm, cycles: 8, taper_cycles: 2}']


def test_force_limit_exceeded_only_at_the_highest_frequency_is_refused_before_start():
    p = program(*GRID)
    model = element_force_model()                      # seed000 at 20 degC, the simulated specimen
    slow, fast = model(p.blocks[0]), model(p.blocks[1])
    # K_dyn x A of the analytic steady state is 14.08 kN at 0.5 Hz and 15.12 kN at 1 mm, 14 Hz
    assert 14.08e3 < slow < 14.3e3 and 15.12e3 < fast < 15.4e3
    limits = Limits(force_max=14.8e3)
    check_program(limits, p, FS)                        # no force prediction: passes
    with pytest.raises(LimitError) as exc:
        check_program(limits, p, FS, force_model=model)
    msg = str(exc.value)
    assert "block 1 'fast'" in msg and f'{fast:.6g} N' in msg and '14 Hz' in msg and 'force_max 14800 N' in msg
    with pytest.raises(LimitError, match="block 1 'fast'.*predicted peak force"):
        ProgramRunner(p, FS, Limits(force_max=14.8e3, force_model=model))
    check_program(Limits(force_max=15.5e3, force_model=model), p, FS)
    # a preload adds k0 |mean|: 1 mm more mean at 0.5 Hz adds 12.3 kN
    pre = program('{waveform: ramp, target: 1 mm, rate: 1 mm/s}',
                  '{name: pre, waveform: sine, frequency: 0.5 Hz, amplitude: 1 mm, cycles: 2}')
    assert model(pre.blocks[1]) == pytest.approx(slow + 12.29e3, rel=1e-9)


@pytest.mark.parametrize('block', GRID + WAVES[1:4])
def test_force_model_matches_a_time_domain_run_of_the_element(block):
    """The estimate is within 0.5 % of the model's peak force over the block run from rest."""
    p = program(block)
    blk = p.blocks[0]
    fs = 5000.0
    x = blk.evaluate(np.arange(blk.n_samples(fs)) / fs)
    sim = build_model({'model': 'seed000', 'values': load_parameter_set('seed000_20C').as_dict()}, 1 / fs).run(x)
    assert element_force_model()(blk) == pytest.approx(float(np.max(np.abs(sim))), rel=5e-3)
