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

"""Compensation memory of the amplitude loop: lookup rules (log-frequency interpolation, conservative
extrapolation, nearest amplitude per frequency, waveform separation) and the runner starting each block from
what earlier blocks learned, with setpoints generated 0.5 s ahead of the measurement. No rig: the plant is a
per-frequency gain applied to the command."""
import math

import numpy as np
import pytest

from rubber_rig.excitation import Program, ProgramRunner
from rubber_rig.excitation.compensation import CompensationMemory
from rubber_rig.safety import Limits

FS = 1000.0


def block(text):
    return Program.from_yaml_text(f'blocks:\n  - {text}\n').blocks[0]


def sine(f, a='0.5 mm', mean='0 mm'):
    return block(f'{{waveform: sine, frequency: {f} Hz, amplitude: {a}, mean: {mean}, cycles: 8}}')


def test_lookup_interpolates_in_log_frequency():
    m = CompensationMemory()
    assert m.lookup(sine(10)) is None
    m.learn(0, sine(8), 1.01, 1e-6)
    assert m.lookup(sine(10)) == (1.01, 1e-6)            # a single point is used as it is
    m.learn(1, sine(16), 1.03, 3e-6)
    g, o = m.lookup(sine(8 * math.sqrt(2)))              # halfway in log-frequency
    assert g == pytest.approx(1.02, abs=1e-12) and o == pytest.approx(2e-6, abs=1e-15)
    assert m.lookup(sine(8))[0] == pytest.approx(1.01, abs=1e-12)
    assert m.lookup(sine(8.05))[0] == pytest.approx(1.01 + 0.02 * math.log(8.05 / 8) / math.log(2), abs=1e-12)


def test_extrapolation_is_linear_in_log_frequency_but_at_most_one_span():
    m = CompensationMemory()
    m.learn(0, sine(10), 1.00, 0.0)
    m.learn(1, sine(12), 1.01, 0.0)
    slope = 0.01 / math.log(1.2)
    assert m.lookup(sine(14))[0] == pytest.approx(1.01 + slope * math.log(14 / 12), abs=1e-12)
    # far beyond: the correction never exceeds what the two nearest points differ by
    assert m.lookup(sine(40))[0] == pytest.approx(1.02, abs=1e-12)
    assert m.lookup(sine(2))[0] == pytest.approx(0.99, abs=1e-12)
    # two nearly equal frequencies (noisy slope) extrapolate hardly at all
    m2 = CompensationMemory()
    m2.learn(0, sine(10), 1.00, 0.0)
    m2.learn(1, sine(10.2), 1.02, 0.0)
    assert m2.lookup(sine(30))[0] == pytest.approx(1.04, abs=1e-12)


def test_per_frequency_the_nearest_amplitude_is_used_and_waveforms_are_separate():
    m = CompensationMemory()
    m.learn(0, sine(10, '0.5 mm'), 1.01, 0.0)
    m.learn(1, sine(10, '1 mm'), 1.02, 0.0)
    m.learn(2, sine(12, '0.5 mm'), 1.03, 0.0)
    assert m.lookup(sine(10, '0.9 mm'))[0] == pytest.approx(1.02)
    assert m.lookup(sine(10, '0.6 mm'))[0] == pytest.approx(1.01)
    m.learn(5, sine(10.05, '0.5 mm'), 1.00, 0.0)    # within 1 % of 10 Hz: the same column, 1 mm nearer
    assert m.lookup(sine(10.05, '1 mm'))[0] == pytest.approx(1.02 + 0.01 * math.log(1.005) / math.log(1.2))
    assert m.lookup(sine(12, '1 mm'))[0] == pytest.approx(1.03)      # only 0.5 mm learned at 12 Hz
    tri = block('{waveform: triangle, frequency: 10 Hz, amplitude: 1 mm, cycles: 2}')
    assert m.lookup(tri) is None
    sweep = block('{waveform: sweep_log, f_start: 2 Hz, f_end: 20 Hz, duration: 1 s, amplitude: 0.3 mm}')
    m.learn(3, sweep, 1.5, 0.0)
    assert m.lookup(sweep) is None and len(m.entries()) == 4
    m.learn(4, tri, 1.1, 0.0)
    assert m.lookup(tri)[0] == pytest.approx(1.1) and m.lookup(sine(10, '1 mm'))[0] == pytest.approx(1.02)


PLANT = {8.0: 0.9936, 10.0: 0.990, 12.0: 0.9856, 14.0: 0.9804}     # 1 - 1e-4 f^2: about 2 % short at 14 Hz


def run_with_latency(prog, plant, latency=500, chunk=50, limits=None, **kw):
    """Runner against a plant that scales each block's command by plant[frequency]; the runner sees each
    sample `latency` samples after generating it (the excitation node's lead_time 0.5 s at 1 kHz)."""
    r = ProgramRunner(prog, FS, limits or Limits(), amplitude_control=True, **kw)
    gain = {b: plant.get(blk.frequency, 1.0) for b, blk in enumerate(prog.blocks)}
    measured, fed, out = [], 0, []
    while not r.finished:
        x = r.next_setpoints(chunk)
        out.append(x)
        measured.append(np.where(r.last_block_index >= 0,
                                 x * np.array([gain.get(int(b), 1.0) for b in r.last_block_index]), x))
        m = np.concatenate(measured)
        upto = max(r.sequence - latency, fed)
        r.feed_measurement(fed, m[fed:upto])
        fed = upto
    m = np.concatenate(measured)
    r.feed_measurement(fed, m[fed:])
    return r, np.concatenate(out)


def ascending(amplitude='0.5 mm'):
    return Program.from_yaml_text('name: asc\nblocks:\n' + ''.join(
        f'  - {{name: s{f}, waveform: sine, frequency: {f} Hz, amplitude: {amplitude}, cycles: 8}}\n'
        for f in (8, 10, 12, 14)))


def test_runner_starts_each_block_from_what_earlier_blocks_learned():
    prog = ascending()
    r, _ = run_with_latency(prog, PLANT)
    err = [s.achieved_amplitude / s.target_amplitude - 1 for s in r.block_summaries]
    assert all(abs(e) < 0.01 for e in err[1:]), err
    assert all(abs(e) < 0.002 for e in err[2:]), err          # interpolated/extrapolated from learned points
    learned = {round(e.frequency): e.gain for e in r.compensation.entries()}
    for f, g in PLANT.items():
        assert learned[f] == pytest.approx(1 / g, rel=1e-6)   # the exact plant of every block was learned
    # without the memory every block starts at gain 1: the correction arrives too late at 14 Hz
    r0, _ = run_with_latency(prog, PLANT, compensation_memory=False)
    assert r0.compensation is None
    assert r0.block_summaries[3].achieved_amplitude / 0.5e-3 - 1 < -0.015


def test_memory_start_gain_is_capped_by_the_limits():
    prog = Program.from_yaml_text('blocks:\n'
                                  '  - {waveform: sine, frequency: 8 Hz, amplitude: 0.9 mm, cycles: 8}\n'
                                  '  - {waveform: sine, frequency: 10 Hz, amplitude: 0.9 mm, cycles: 8}\n')
    lim = Limits(displacement_min=-1e-3, displacement_max=1e-3)
    r, x = run_with_latency(prog, {8.0: 0.5, 10.0: 0.5}, limits=lim)   # would need gain 2
    assert r.compensation.entries()[0].gain == pytest.approx(2.0)
    assert r.state == 'finished' and not r.aborted
    assert np.max(np.abs(x)) <= 1e-3 + 1e-15
    assert r._loops[1].initial[0] == pytest.approx(1e-3 / 0.9e-3)


def test_open_loop_setpoints_do_not_depend_on_the_memory_option():
    prog = ascending()
    plain = ProgramRunner(prog, FS, Limits(), amplitude_control=False, compensation_memory=True)
    assert plain.compensation is None
    np.testing.assert_array_equal(plain.next_setpoints(prog.n_samples(FS)), prog.setpoints(FS))


def test_equally_near_entries_the_most_recently_learned_wins():
    m = CompensationMemory()
    m.learn(0, sine(10), 1.01, 0.0)
    m.learn(1, sine(10), 1.02, 0.0)
    assert m.lookup(sine(10))[0] == 1.02
    m.learn(0, sine(10), 1.03, 0.0)                   # block 0 ran again (hold/resume): its update is newest
    assert m.lookup(sine(10))[0] == 1.03
