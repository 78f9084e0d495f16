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

"""Waveforms generated from the sample index: shape, rate, sweeps, mean offset, taper (no step, no velocity
jump). Pure excitation, no rig."""
import math

import numpy as np
import pytest

from rubber_rig.excitation import Program

FS = 1000.0


def prog(block_yaml, extra=''):
    return Program.from_yaml_text(f'name: t\n{extra}blocks:\n  - {block_yaml}\n')


def steps_ok(x, fs, v_max):
    """No step: every sample-to-sample move is below v_max / fs."""
    return float(np.max(np.abs(np.diff(x)))) <= v_max / fs * (1 + 1e-9)


def test_sine_amplitude_frequency_cycles_and_taper():
    p = prog('{waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 4, taper_cycles: 1}')
    blk = p.blocks[0]
    x = p.setpoints(FS)
    assert x.size == 1200                         # (4 + 2 * 1) cycles / 5 Hz * 1 kHz
    assert p.duration(FS) == pytest.approx(1.2)
    steady = x[200:1000]                           # the 4 full-amplitude cycles
    t = np.arange(200, 1000) / FS
    np.testing.assert_allclose(steady, 1e-3 * np.sin(2 * np.pi * 5 * t), atol=1e-12)
    # taper: starts and ends at the mean with zero velocity and no acceleration jump
    assert abs(x[0]) < 1e-12 and abs(x[-1]) < 1e-8
    v = np.diff(x) * FS
    assert abs(v[0]) < 1e-4 and abs(v[-1]) < 1e-3   # [m/s], vs 31 mm/s peak
    assert steps_ok(x, FS, 2 * math.pi * 5 * 1e-3 * 1.01)
    assert blk.total_cycles == 6


def test_mean_offset_preload():
    p = Program.from_yaml_text("""
name: preload
blocks:
  - {waveform: ramp, target: -1.1 mm, rate: 0.5 mm/s}
  - {waveform: sine, frequency: 4 Hz, amplitude: 0.5 mm, cycles: 3}
""")
    assert p.blocks[1].mean == pytest.approx(-1.1e-3)
    starts = p.block_starts(FS)
    sine = p.setpoints(FS, int(starts[1]), int(starts[2]))
    t = np.arange(sine.size) / FS
    steady = (t >= 0.25) & (t < 1.0)
    np.testing.assert_allclose(sine[steady], -1.1e-3 + 0.5e-3 * np.sin(2 * np.pi * 4 * t[steady]), atol=1e-12)
    ramp = p.setpoints(FS, 0, int(starts[1]))
    assert ramp[0] == 0.0 and ramp[-1] == pytest.approx(-1.1e-3)
    # raised-cosine ramp: peak velocity equals the set rate, zero velocity at both ends
    v = np.diff(ramp) * FS
    assert np.max(np.abs(v)) == pytest.approx(0.5e-3, rel=2e-3)
    assert abs(v[0]) < 1e-6 and abs(v[-1]) < 1e-6


def test_triangle_quasi_static_constant_velocity():
    # seed 001: 0.05 mm/s quasi-static triangle
    p = prog('{waveform: triangle, rate: 0.05 mm/s, amplitude: 0.2 mm, cycles: 1, taper_cycles: 0.5}')
    blk = p.blocks[0]
    assert blk.frequency == pytest.approx(0.05e-3 / (4 * 0.2e-3))   # 0.0625 Hz
    x = p.setpoints(100.0)
    t = np.arange(x.size) / 100.0
    ph = blk.frequency * t
    steady = (ph >= 0.5 + 0.02) & (ph < 1.5 - 0.02)
    v = np.abs(np.diff(x) * 100.0)[steady[:-1]]
    corners = np.abs(np.mod(ph[:-1][steady[:-1]], 0.5) - 0.25) < 0.01   # peaks at phase 0.25, 0.75
    assert np.allclose(v[~corners], 0.05e-3, rtol=1e-9)
    assert x.max() == pytest.approx(0.2e-3, rel=1e-3)


def test_square_trapezoid_with_set_rate():
    p = prog('{waveform: square, frequency: 1 Hz, amplitude: 1 mm, rate: 20 mm/s, cycles: 2}')
    x = p.setpoints(FS)
    v = np.abs(np.diff(x)) * FS
    assert v.max() == pytest.approx(20e-3, rel=1e-6)          # edges at the set rate
    t = np.arange(x.size) / FS
    plateau = (t > 1.2) & (t < 1.35)                          # cycle 2 (steady), top plateau around 0.25
    np.testing.assert_allclose(x[plateau], 1e-3, atol=1e-12)
    assert abs(x[0]) < 1e-12


@pytest.mark.parametrize('kind', ['sweep_lin', 'sweep_log'])
def test_sweeps_follow_their_frequency_law(kind):
    p = prog(f'{{waveform: {kind}, f_start: 1 Hz, f_end: 20 Hz, duration: 10 s, amplitude: 0.3 mm, '
             f'taper_cycles: 1}}')
    blk = p.blocks[0]
    x = p.setpoints(FS)
    assert x.size == int(math.ceil((1 / 1 + 10 + 1 / 20) * FS - 1e-9))
    # instantaneous frequency from upward zero crossings vs the law
    t = np.arange(x.size) / FS
    up = np.where((x[:-1] < 0) & (x[1:] >= 0))[0]
    tc = t[up] - x[up] / ((x[up + 1] - x[up]) * FS)
    f_meas = 1 / np.diff(tc)
    tm = 0.5 * (tc[1:] + tc[:-1])
    sel = (tm > 1.5) & (tm < 10.5)
    f_law = blk.frequency_at(tm[sel])
    np.testing.assert_allclose(f_meas[sel], f_law, rtol=0.01)
    if kind == 'sweep_log':
        mid = blk.frequency_at(np.array([1.0 + 5.0]))[0]
        assert mid == pytest.approx(math.sqrt(20), rel=1e-9)     # geometric mean half way
    assert abs(x[0]) < 1e-12 and abs(x[-1]) < 1e-6     # last sample: within 1 um of the mean


def test_hold_dwell_keeps_level():
    p = Program.from_yaml_text("""
blocks:
  - {waveform: ramp, target: 0.4 mm, duration: 1 s}
  - {waveform: hold, duration: 0.5 s}
""")
    starts = p.block_starts(FS)
    hold = p.setpoints(FS, int(starts[1]), int(starts[2]))
    assert hold.size == 500 and np.all(hold == pytest.approx(0.4e-3))


def test_block_transitions_have_no_step_or_velocity_jump():
    p = Program.from_yaml_text("""
blocks:
  - {waveform: sine, frequency: 8 Hz, amplitude: 1 mm, cycles: 3, taper_cycles: 2}
  - {waveform: sweep_log, f_start: 2 Hz, f_end: 12 Hz, duration: 2 s, amplitude: 0.5 mm}
  - {waveform: triangle, frequency: 2 Hz, amplitude: 0.5 mm, cycles: 2}
  - {waveform: ramp, target: 1 mm, rate: 5 mm/s}
  - {waveform: square, frequency: 1 Hz, amplitude: 0.5 mm, rate: 10 mm/s, cycles: 1}
""")
    x = p.setpoints(FS)
    v = np.diff(x) * FS
    a = np.diff(v) * FS
    for b in p.block_starts(FS)[1:-1]:
        b = int(b)
        assert abs(x[b] - x[b - 1]) < 1e-6                      # < 1 um between samples at the joint
        assert abs(v[b] - v[b - 2]) < 2e-3                      # no velocity jump across the joint [m/s]
    assert np.max(np.abs(a[:int(p.block_starts(FS)[1])])) < 1.05 * (2 * math.pi * 8) ** 2 * 1e-3
