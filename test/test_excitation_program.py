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

"""Test programs: shipped seed programs, validation errors naming block and field, limits, and the runner
(chunks from the sample index, limit enforcement, abort ramp, hold/resume). No rig."""
import math

import numpy as np
import pytest

from rubber_rig.excitation import Program, ProgramError, ProgramRunner, check_program, load_program, shipped_programs
from rubber_rig.safety import LimitError, Limits

FS = 1000.0


def test_shipped_programs_load_and_fit_default_limits():
    names = shipped_programs()
    for n in ('dynamic_stiffness_grid', 'quasi_static_then_sine', 'log_sweeps_1_50hz', 'preload_sine_grid',
              'durability_10hz'):
        assert n in names
    for n in names:
        p = load_program(n)
        check_program(Limits(), p, FS)          # +-5 mm, 0.2 m/s
        # characterisation programs take minutes; a durability program runs until its detector ends it
        longest = 3 * 3600 if n.startswith('durability') else 600
        assert p.description and 0 < p.duration(FS) < longest
    durability = load_program('durability_10hz')
    assert durability.blocks[0].cycles == 100000 and durability.blocks[0].frequency == 10.0
    actions = {(d.type, d.action) for d in durability.all_detectors()}
    assert actions >= {('stiffness_change', 'end'), ('residual', 'hold')}


def test_programs_renamed_by_what_they_test_still_load_by_their_earlier_names():
    from rubber_rig.excitation.program import PROGRAM_ALIASES
    assert set(PROGRAM_ALIASES.values()) <= set(shipped_programs())
    assert not set(PROGRAM_ALIASES) & set(shipped_programs())        # an old name never shadows a program
    for old, new in PROGRAM_ALIASES.items():
        a, b = load_program(old), load_program(new)
        assert a.name == b.name == new and a.duration(FS) == b.duration(FS) and len(a.blocks) == len(b.blocks)
    with pytest.raises(FileNotFoundError, match="no program 'seed002_grid'.*dynamic_stiffness_grid"):
        load_program('seed002_grid')


def test_dynamic_stiffness_grid_is_the_paper_protocol():
    p = load_program('dynamic_stiffness_grid')
    amps = sorted({b.amplitude for b in p.blocks})
    freqs = sorted({b.frequency for b in p.blocks})
    assert amps == pytest.approx([0.5e-3, 1.0e-3])
    assert freqs[0] == 0.5 and freqs[-1] == 14.0
    assert len(p.blocks) == len(amps) * len(freqs)
    assert all(b.waveform == 'sine' and b.mean == 0.0 for b in p.blocks)
    assert p.blocks[0].name == 'sine_0.5mm_0.5Hz'


def test_seed004_sines_sit_on_the_preloads_and_seed001_starts_quasi_static():
    p = load_program('preload_sine_grid')
    means = sorted({round(b.mean * 1e3, 6) for b in p.blocks if b.waveform == 'sine'})
    assert means == [-1.3, -1.1, -0.9]
    q = load_program('quasi_static_then_sine')
    assert q.blocks[0].waveform == 'triangle' and q.blocks[0].rate == pytest.approx(0.05e-3)
    s = load_program('log_sweeps_1_50hz')
    sweeps = [b for b in s.blocks if b.waveform == 'sweep_log']
    assert [b.amplitude for b in sweeps] == pytest.approx([0.2e-3, 0.3e-3, 0.5e-3])
    assert all(b.frequency == 1.0 and b.frequency_end == 50.0 for b in sweeps)


@pytest.mark.parametrize('blocks, where, fld', [
    ('- {waveform: sine, frequency: 5 Hz, amplitude: 1 mm}', "block 0 'sine_0'", 'cycles'),
    ('- {waveform: sinus, frequency: 5}', 'block 0', 'waveform'),
    ('- {name: a, waveform: sine, frequency: -5 Hz, amplitude: 1 mm, cycles: 2}', "block 0 'a'", 'frequency'),
    ('- {name: a, waveform: sine, frequency: 5 Hz, amplitude: 1 kN, cycles: 2}', "block 0 'a'", 'amplitude'),
    ('- {name: a, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 2.5}', "block 0 'a'", 'cycles'),
    ('- {name: a, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 2, taper_cycles: 0}', "block 0 'a'",
     'taper_cycles'),
    ('- {name: a, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 2, colour: red}', "block 0 'a'",
     'colour'),
    ('- {name: a, waveform: hold, duration: 1 s}\n  - {name: b, waveform: sine, frequency: 5 Hz, amplitude: 1 mm,'
     ' cycles: 2, mean: 1 mm}', "block 1 'b'", 'mean'),
    ('- {name: q, waveform: square, frequency: 5 Hz, amplitude: 1 mm, cycles: 2, rate: 1 mm/s}', "block 0 'q'",
     'rate'),
    ('- {name: r, waveform: ramp, target: 1 mm}', "block 0 'r'", 'rate'),
    ('- {name: s, waveform: sweep_log, f_start: 1 Hz, amplitude: 1 mm, duration: 5 s}', "block 0 's'", 'f_end'),
    ('- {name: h, waveform: hold, duration: 1 s, amplitude: 1 mm}', "block 0 'h'", 'amplitude'),
])
def test_bad_programs_name_block_and_field(blocks, where, fld):
    with pytest.raises(ProgramError) as exc:
        Program.from_yaml_text(f'name: bad\nblocks:\n  {blocks}\n')
    msg = str(exc.value)
    assert msg.startswith(where) and f"field '{fld}'" in msg, msg


def test_programs_take_the_units_of_the_command_line():
    """One units table: what `rubber-rig props` reads (cm, us, mHz) a program reads too, into the same SI."""
    p = Program.from_yaml_text('name: u\nblocks:\n  - {name: a, waveform: sine, frequency: 500 mHz, '
                               'amplitude: 0.1 cm, cycles: 2}\n  - {name: b, waveform: hold, duration: 250000 us}\n')
    assert p.blocks[0].frequency == pytest.approx(0.5) and p.blocks[0].amplitude == pytest.approx(1e-3)
    assert p.blocks[1].duration == pytest.approx(0.25)


def test_bad_program_structure():
    for text, fld in [('blocks: []', 'blocks'), ('name: x\nspeed: 3\nblocks: []', 'speed'),
                      ('blocks: [1, 2]', None), ('[', None)]:
        with pytest.raises(ProgramError) as exc:
            Program.from_yaml_text(text)
        if fld:
            assert f"'{fld}'" in str(exc.value)
    with pytest.raises(FileNotFoundError, match='dynamic_stiffness_grid'):
        load_program('no_such_program')


def test_limits_checked_before_start_name_the_block():
    p = Program.from_yaml_text("""
blocks:
  - {name: ok, waveform: sine, frequency: 1 Hz, amplitude: 1 mm, cycles: 1}
  - {name: fast, waveform: sine, frequency: 30 Hz, amplitude: 1 mm, cycles: 1}
""")
    with pytest.raises(LimitError, match="block 1 'fast'.*velocity"):
        ProgramRunner(p, FS, Limits(velocity_max=0.1))
    with pytest.raises(LimitError, match="block 0 'ok'.*displacement"):
        check_program(Limits(displacement_min=-0.5e-3, displacement_max=0.5e-3), p, FS)
    with pytest.raises(LimitError, match='predicted force'):
        check_program(Limits(velocity_max=1.0, force_max=10e3, stiffness_estimate=1.3e7), p, FS)
    with pytest.raises(LimitError, match='displacement_min'):
        Limits(displacement_min=1e-3, displacement_max=0.0)


def test_runner_chunks_equal_whole_program_from_sample_index():
    p = load_program('preload_sine_grid')
    r = ProgramRunner(p, FS, Limits(velocity_max=0.5))
    n = 7000
    sizes = np.random.default_rng(1).integers(1, 300, 100)
    out, got = [], 0
    for s in sizes:
        s = int(min(s, n - got))
        out.append(r.next_setpoints(s))
        got += s
        if got >= n:
            break
    np.testing.assert_array_equal(np.concatenate(out), p.setpoints(FS, 0, n))
    assert r.sequence == n


def test_runner_abort_is_smooth_ramp_to_rest():
    p = Program.from_yaml_text('blocks:\n  - {waveform: sine, frequency: 10 Hz, amplitude: 1 mm, cycles: 50}\n')
    lim = Limits(velocity_max=0.2)
    r = ProgramRunner(p, FS, lim)
    a = r.next_setpoints(333)       # mid-cycle, moving fast
    r.abort('operator')
    b = r.next_setpoints(4000)
    x = np.concatenate([a, b])
    v = np.diff(x) * FS
    assert r.finished and r.aborted
    assert abs(b[-1]) == 0.0
    assert np.max(np.abs(np.diff(x))) <= lim.velocity_max / FS              # no step
    acc = np.diff(v) * FS
    assert np.max(np.abs(acc[330:])) <= 20.0 + 1e-6                         # bounded deceleration, no jump
    assert r.block_summaries[0].completed is False and 'operator' in r.block_summaries[0].message


def test_runner_hold_and_resume_restart_block_smoothly():
    p = Program.from_yaml_text('blocks:\n  - {waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 5}\n')
    r = ProgramRunner(p, FS, Limits())
    a = r.next_setpoints(430)
    r.hold()
    b = r.next_setpoints(2000)
    assert r.state == 'holding' and abs(b[-1]) < 1e-12
    r.resume()
    c = r.next_setpoints(1400)
    x = np.concatenate([a, b, c])
    assert np.max(np.abs(np.diff(x))) * FS < 0.05
    np.testing.assert_allclose(c, p.setpoints(FS, 0, 1400), atol=1e-12)   # block restarted with its taper
    assert r.finished


def test_runner_turns_a_limit_violation_into_an_abort():
    # amplitude control would have to push beyond the displacement limit: the runner caps, never exceeds
    p = Program.from_yaml_text('blocks:\n  - {waveform: sine, frequency: 5 Hz, amplitude: 0.9 mm, cycles: 40}\n')
    lim = Limits(displacement_min=-1e-3, displacement_max=1e-3)
    r = ProgramRunner(p, FS, lim, amplitude_control=True)
    x = r.next_setpoints(500)
    # a plant that only reaches 50 %: the loop asks for gain 2, capped at the 1 mm limit
    for _ in range(10):
        r.feed_measurement(r.sequence - 500, 0.5 * x)
        x = r.next_setpoints(500)
        assert np.max(np.abs(x)) <= 1e-3 + 1e-15
    assert r.state == 'running'


def test_progress_and_summaries_report_cycles():
    p = Program.from_yaml_text('blocks:\n  - {name: s, waveform: sine, frequency: 10 Hz, amplitude: 1 mm, '
                               'cycles: 6}\n  - {waveform: hold, duration: 0.1 s}\n')
    r = ProgramRunner(p, FS, Limits())
    x = r.next_setpoints(450)
    pr = r.progress
    assert (pr.block_index, pr.block_name, pr.cycles_total) == (0, 's', 6)
    assert pr.cycle == 4 and 0 < pr.fraction < 1
    r.feed_measurement(0, 0.98 * x)
    x2 = r.next_setpoints(r.program.n_samples(FS) - 450)
    r.feed_measurement(450, 0.98 * x2)
    s = r.block_summaries[0]
    assert s.completed and s.cycles_measured == 6
    assert s.achieved_amplitude == pytest.approx(0.98e-3, rel=1e-9)
    assert math.isnan(r.block_summaries[1].achieved_amplitude)


def test_block_to_dict_is_the_inverse_of_parse_block():
    """Every waveform round-trips through Block.to_dict (what tools that rewrite programs rely on)."""
    from rubber_rig.excitation import WAVEFORMS
    from rubber_rig.excitation.program import with_overrides
    text = ('name: all\nblocks:\n'
            '  - {name: a, waveform: sine, frequency: 2 Hz, amplitude: 1 mm, cycles: 3, taper_cycles: 2}\n'
            '  - {name: b, waveform: triangle, rate: 4 mm/s, amplitude: 0.5 mm, cycles: 2}\n'
            '  - {name: c, waveform: triangle, frequency: 1 Hz, amplitude: 0.5 mm, cycles: 2}\n'
            '  - {name: d, waveform: square, frequency: 1 Hz, rate: 20 mm/s, amplitude: 0.5 mm, cycles: 2}\n'
            '  - {name: e, waveform: sweep_lin, f_start: 1 Hz, f_end: 5 Hz, duration: 4 s, amplitude: 0.5 mm}\n'
            '  - {name: f, waveform: sweep_log, f_start: 1 Hz, f_end: 8 Hz, duration: 4 s, amplitude: 0.5 mm}\n'
            '  - {name: g, waveform: hold, duration: 1 s}\n'
            '  - {name: h, waveform: ramp, target: 1 mm, rate: 2 mm/s}\n'
            '  - {name: i, waveform: ramp, target: 0 mm, duration: 2 s}\n'
            '  - {name: j, waveform: haversine, frequency: 2 Hz, amplitude: 0.5 mm, cycles: 2}\n'
            '  - {name: k, waveform: multisine, frequency: 0.5 Hz, f_start: 1 Hz, f_end: 5 Hz, amplitude: 0.5 mm,'
            ' cycles: 2, seed: 7}\n')
    p = Program.from_yaml_text(text)
    again, _ = with_overrides(p)
    assert again.blocks == p.blocks and {b.waveform for b in p.blocks} == set(WAVEFORMS)
    short, _ = with_overrides(p, cycles=1, duration_scale=0.5, blocks='0,6-8', taper_cycles=1)
    assert [b.name for b in short.blocks] == ['a', 'g', 'h', 'i']
    assert short.blocks[0].cycles == 1 and short.blocks[0].taper_cycles == 1
    assert short.blocks[1].duration == 0.5 and short.blocks[3].duration == 2.0        # ramps keep their time


def test_parse_block_of_to_dict_gives_the_same_block_for_every_waveform():
    """parse_block(b.to_dict()) == b, field by field, for each waveform (both ways of giving a triangle and a ramp),
    also about a mean other than 0 and through YAML text (what a rewritten program is sent as)."""
    import yaml

    from rubber_rig.excitation import WAVEFORMS
    from rubber_rig.excitation.blocks import parse_block
    text = ('name: all\nblocks:\n'
            '  - {name: up, waveform: ramp, target: 1.5 mm, duration: 1 s}\n'
            '  - {waveform: sine, frequency: 7 Hz, amplitude: 0.3 mm, cycles: 5, taper_cycles: 1.5}\n'
            '  - {name: tr, waveform: triangle, rate: 3 mm/s, amplitude: 0.7 mm, cycles: 2}\n'
            '  - {name: tf, waveform: triangle, frequency: 0.25 Hz, amplitude: 0.5 mm, cycles: 1}\n'
            '  - {name: sq, waveform: square, frequency: 2 Hz, rate: 50 mm/s, amplitude: 0.4 mm, cycles: 3}\n'
            '  - {name: sl, waveform: sweep_lin, f_start: 10 Hz, f_end: 2 Hz, duration: 3 s, amplitude: 0.2 mm}\n'
            '  - {name: sg, waveform: sweep_log, f_start: 0.5 Hz, f_end: 30 Hz, duration: 6 s, amplitude: 0.1 mm,'
            ' taper_cycles: 3}\n'
            '  - {name: h, waveform: dwell, duration: 0.25 s}\n'
            '  - {name: down, waveform: ramp, target: -0.5 mm, rate: 4 mm/s}\n'
            '  - {name: hv, waveform: haversine, frequency: 3 Hz, amplitude: 0.4 mm, cycles: 4, taper_cycles: 2}\n'
            '  - {name: ms, waveform: multisine, frequency: 0.25 Hz, f_start: 0.5 Hz, f_end: 12 Hz, amplitude: 0.3 mm,'
            ' cycles: 3, seed: 11}\n')
    blocks = Program.from_yaml_text(text).blocks
    assert {b.waveform for b in blocks} == set(WAVEFORMS)
    assert blocks[1].mean == pytest.approx(1.5e-3) and blocks[4].square_slope > 1
    for b in blocks:
        d = b.to_dict()
        assert parse_block(d, b.index, b.start_level, {}) == b, b.name
        assert parse_block(yaml.safe_load(yaml.safe_dump(d)), b.index, b.start_level, {}) == b, b.name
    assert 'rate' in blocks[2].to_dict() and 'frequency' not in blocks[2].to_dict()       # given as it was
    assert 'rate' in blocks[8].to_dict() and 'duration' not in blocks[8].to_dict()
