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

"""Detectors without ROS: declarations, the Monitor's judgement cycle by cycle, the simulated specimen's damage
laws and the runner's cycle bookkeeping across a hold. The same code runs in the excitation node
(test_detectors_nodes.py drives it through separate node processes).
"""
import math

import numpy as np
import pytest

from rubber_rig.excitation.blocks import ProgramError
from rubber_rig.excitation.detector_specs import DEFAULTS, DetectorError, parse_detector, parse_detectors, with_defaults
from rubber_rig.excitation.detectors import Cycle, Monitor, blind_for, strongest
from rubber_rig.excitation.program import read_program, with_overrides
from rubber_rig.excitation.runner import ProgramRunner
from rubber_rig.rig.options import ConfigError, DamageSpec
from rubber_rig.rig.sim.damage import DamagedSpecimen
from rubber_rig.rig.sim.specimen import LinearSpecimen

K = 1.4e7      # [N/m] a specimen's dynamic stiffness
C = 1.0e4      # [N s/m]


# ---- declarations --------------------------------------------------------------------------------------------------
def test_defaults_follow_the_type():
    r, s, f, t = parse_detectors([{'type': 'residual'}, {'type': 'stiffness_change'},
                                  {'type': 'force_drift', 'threshold': '2 kN'},
                                  {'type': 'elapsed_time', 'threshold': '2 h'}], 'program')
    assert (r.action, r.threshold, r.reference) == ('hold', 4.0, 'stabilised')
    assert (s.action, s.threshold, s.quantity, s.reference) == ('end', 0.2, 'k_dyn', 'program')
    assert (f.threshold, f.threshold_units, f.quantity) == (2000.0, 'N', 'mean')
    assert (t.action, t.threshold) == ('end', 7200.0)
    frac = parse_detector({'type': 'force_drift', 'threshold': 0.1, 'quantity': 'amplitude'}, 'x')
    assert (frac.threshold, frac.threshold_units) == (0.1, '')
    assert frac.to_dict()['threshold'] == 0.1 and f.to_dict()['threshold'] == '2000 N'
    assert parse_detectors(None, 'program') == []


@pytest.mark.parametrize('raw, field', [
    ({'type': 'residal'}, "'type'"),
    ({'type': 'residual', 'treshold': 3}, "'treshold'"),
    ({'type': 'residual', 'action': 'stop'}, "'action'"),
    ({'type': 'force_drift'}, "'threshold': required"),
    ({'type': 'cycle_count'}, "'threshold': required"),
    ({'type': 'residual', 'threshold': -1}, "'threshold': must be > 0"),
    ({'type': 'residual', 'threshold': float('nan')}, "'threshold'"),
    ({'type': 'elapsed_time', 'threshold': '2 parsecs'}, "'threshold'"),
    ({'type': 'residual', 'consecutive': 0}, "'consecutive'"),
    ({'type': 'residual', 'settle_cycles': 2.5}, "'settle_cycles'"),
    ({'type': 'residual', 'quantity': 'k_dyn'}, "'quantity': not used"),
    ({'type': 'stiffness_change', 'quantity': 'mass'}, "'quantity'"),
    ({'type': 'residual', 'reference': 'model'}, "'reference'"),
    ({'type': 'stiffness_change', 'reference': 'yesterday'}, "'reference'"),
    ({'type': 'residual', 'floor': 1.5}, "'noise'/'floor'"),
    ('residual', 'expected a mapping'),
])
def test_a_bad_declaration_names_where_and_the_field(raw, field):
    with pytest.raises(DetectorError) as err:
        parse_detectors([raw], "block 2 'durability'")
    assert str(err.value).startswith("block 2 'durability': detectors[0]") and field in str(err.value)


def test_duplicate_names_and_a_non_list_are_refused():
    with pytest.raises(DetectorError, match="two detectors named 'residual'"):
        parse_detectors([{'type': 'residual'}, {'type': 'residual', 'threshold': 6}], 'program')
    with pytest.raises(DetectorError, match="field 'detectors': expected a list"):
        parse_detectors({'type': 'residual'}, 'program')


PROGRAM = """
name: durability_test
detectors: [{type: elapsed_time, threshold: 1 h}]
blocks:
  - {name: settle, waveform: sine, amplitude: 1 mm, frequency: 2 Hz, cycles: 4}
  - name: durability
    waveform: sine
    amplitude: 1 mm
    frequency: 10 Hz
    cycles: 100000
    detectors:
      - {type: stiffness_change, threshold: 0.2, action: end}
      - {type: residual, threshold: 5, action: warn}
"""


def test_program_and_block_detectors_survive_a_rewrite():
    program, _ = read_program(yaml_text=PROGRAM)
    got = [(d.name, d.block) for d in program.all_detectors()]
    assert got == [('elapsed_time', -1), ('stiffness_change', 1), ('residual', 1)]
    again, text = with_overrides(program, cycles=10)
    assert "detectors" in text
    assert [(d.name, d.block, d.threshold) for d in again.all_detectors()] == \
        [('elapsed_time', -1, 3600.0), ('stiffness_change', 1, 0.2), ('residual', 1, 5.0)]


def test_a_bad_detector_in_a_program_names_the_block():
    bad = PROGRAM.replace('threshold: 5, action: warn', 'threshold: 5, action: explode')
    with pytest.raises(ProgramError, match=r"block 1 'durability': detectors\[1\]: field 'action'"):
        read_program(yaml_text=bad)
    with pytest.raises(ProgramError, match=r"program 'durability_test': detectors\[0\]: field 'threshold'"):
        read_program(yaml_text=PROGRAM.replace('threshold: 1 h', 'threshold: 1 kg'))


# ---- the monitor ---------------------------------------------------------------------------------------------------
def cycle(n, block=0, k=K, k_model=K, residual=50.0, force_mean=0.0, amp=1e-3, steady=True, c_eq=C):
    f_amp = k * amp
    measured = {'k_dyn': k, 'c_eq': c_eq, 'loss_angle': 0.1, 'force_mean': force_mean, 'force_amplitude': f_amp}
    model = {'k_dyn': k_model, 'c_eq': C, 'loss_angle': 0.1, 'force_mean': 0.0, 'force_amplitude': k_model * amp}
    return Cycle(block, n, steady, amp, 0.0, measured, model, residual, target_amplitude=1e-3, target_mean=0.0,
                 elapsed=0.1 * n, program_cycle=n)


def run(monitor, cycles):
    """{cycle number: [detector names tripped on it]} over `cycles`."""
    out = {}
    for c in cycles:
        for e in monitor.on_cycle(c):
            out.setdefault(c.cycle, []).append(e.detector)
    return out


def test_residual_trips_on_the_first_cycle_over_k_times_the_stabilised_level():
    # force amplitude 14 kN: floor 1 % = 140 N is the expected residual while the model fits to 50 N
    m = Monitor(parse_detectors([{'type': 'residual'}], 'program'))
    tripped = run(m, [cycle(n, residual=50.0 if n < 20 else 600.0) for n in range(1, 30)])
    assert tripped == {20: ['residual']}                       # once per block, on the first cycle over 4 x 140 N
    e = m.events[0]
    assert e.reference == pytest.approx(140.0) and e.threshold == pytest.approx(560.0) and e.value == 600.0
    assert e.action == 'hold' and e.units == 'N' and "block 0, cycle 20" in e.message
    # just below the threshold: nothing
    m = Monitor(parse_detectors([{'type': 'residual'}], 'program'))
    assert run(m, [cycle(n, residual=50.0 if n < 20 else 550.0) for n in range(1, 30)]) == {}
    assert m.peak['residual'] == pytest.approx(550.0 / 560.0)          # the margin left: 2 %


def test_residual_uses_the_larger_of_the_stabilised_level_and_the_declared_noise():
    m = Monitor(parse_detectors([{'type': 'residual', 'noise': '300 N', 'floor': 0}], 'program'))
    assert run(m, [cycle(n, residual=50.0 if n < 10 else 1150.0) for n in range(1, 15)]) == {}
    assert run(m, [cycle(n, residual=1250.0) for n in range(15, 17)]) == {15: ['residual']}
    m = Monitor(parse_detectors([{'type': 'residual', 'floor': 0}], 'program'))    # model error 400 N stabilised
    assert run(m, [cycle(n, residual=400.0 if n < 10 else 1500.0) for n in range(1, 15)]) == {}


def test_nothing_is_judged_before_the_reference_or_off_the_steady_part():
    m = Monitor(parse_detectors([{'type': 'stiffness_change', 'reference': 'stabilised'}], 'program'))
    # settle 3 + reference 3: the 6th steady cycle completes the reference; unsteady cycles do not count
    cycles = [cycle(n, steady=False, k=0.1 * K) for n in range(1, 4)] + [cycle(n, k=K) for n in range(4, 10)]
    assert run(m, cycles) == {}
    assert run(m, [cycle(10, k=0.75 * K)]) == {10: ['stiffness_change']}
    assert m.events[0].reference == pytest.approx(K) and m.events[0].value == pytest.approx(0.75 * K)


def test_a_change_while_the_reference_is_gathered_trips_when_it_is_complete():
    # a crack in the 5th steady cycle: the reference (median of cycles 4-6) is the cracked stiffness, but cycle 4
    # judged against it is 43 % off; the residual's reference is the smallest of its cycles
    m = Monitor(parse_detectors([{'type': 'stiffness_change', 'reference': 'stabilised'}, {'type': 'residual'}],
                                'program'))
    cracked = [cycle(n, k=K if n < 5 else 0.7 * K, residual=50.0 if n < 5 else 2000.0) for n in range(1, 10)]
    assert run(m, cracked) == {6: ['stiffness_change', 'residual']}


def test_consecutive_cycles_and_rearm_after_a_hold():
    m = Monitor(parse_detectors([{'type': 'residual', 'consecutive': 2}], 'program'))
    # one bad cycle (a spike) is not two in a row
    trips = run(m, [cycle(n, residual=2000.0 if n in (10, 12, 13) else 50.0) for n in range(1, 20)])
    assert trips == {13: ['residual']}
    assert run(m, [cycle(n, residual=2000.0) for n in range(20, 23)]) == {}         # tripped once per block
    m.rearm()
    assert run(m, [cycle(n, residual=2000.0) for n in range(23, 26)]) == {24: ['residual']}


def test_program_reference_follows_the_model_across_blocks_and_sees_a_change_between_them():
    m = Monitor(parse_detectors([{'type': 'stiffness_change'}], 'program'))
    # the specimen is 5 % stiffer than its model; block 1 runs at an operating point the model says is 30 % stiffer
    assert run(m, [cycle(n, block=0, k=1.05 * K) for n in range(1, 9)]) == {}
    assert run(m, [cycle(n, block=1, k=1.05 * 1.3 * K, k_model=1.3 * K) for n in range(1, 9)]) == {}
    # damaged between blocks: block 2 is 25 % below what the ratio predicts from its first cycle on
    trips = run(m, [cycle(n, block=2, k=0.75 * 1.05 * 1.2 * K, k_model=1.2 * K) for n in range(1, 4)])
    assert trips == {1: ['stiffness_change']}
    e = m.events[0]
    assert e.reference == pytest.approx(1.05 * 1.2 * K) and e.value / e.reference == pytest.approx(0.75)
    # a block-own reference would have learned the damaged value: blind to it
    m = Monitor(parse_detectors([{'type': 'stiffness_change', 'reference': 'stabilised'}], 'program'))
    run(m, [cycle(n, block=0, k=K) for n in range(1, 9)])
    assert run(m, [cycle(n, block=2, k=0.75 * K) for n in range(1, 12)]) == {}


def test_model_reference_and_other_quantities():
    m = Monitor(parse_detectors([{'type': 'stiffness_change', 'reference': 'model', 'threshold': 0.1}], 'x'))
    assert run(m, [cycle(1, k=1.09 * K)]) == {} and run(m, [cycle(2, k=1.11 * K)]) == {2: ['stiffness_change']}
    m = Monitor(parse_detectors([{'type': 'stiffness_change', 'quantity': 'c_eq', 'reference': 'stabilised'}], 'x'))
    assert run(m, [cycle(n, c_eq=C if n < 8 else 1.3 * C) for n in range(1, 10)]) == {8: ['stiffness_change']}
    assert m.events[0].units == 'N s/m'


def test_force_drift_absolute_and_fractional():
    m = Monitor(parse_detectors([{'type': 'force_drift', 'threshold': '2 kN'}], 'x'))
    assert run(m, [cycle(n, force_mean=0.0 if n < 9 else -1900.0) for n in range(1, 10)]) == {}
    assert run(m, [cycle(10, force_mean=-2100.0)]) == {10: ['force_drift']}
    m = Monitor(parse_detectors([{'type': 'force_drift', 'threshold': 0.1}], 'x'))      # 10 % of 14 kN
    assert run(m, [cycle(n, force_mean=0.0 if n < 9 else 1500.0) for n in range(1, 10)]) == {9: ['force_drift']}
    assert m.events[0].threshold == pytest.approx(0.1 * K * 1e-3)
    # preloaded to 30 kN (amplitude 14 kN): 10 % of the preload; a relaxation of 2.5 kN is not a departure
    m = Monitor(parse_detectors([{'type': 'force_drift', 'threshold': 0.1}], 'x'))
    relaxing = [cycle(n, force_mean=30e3 - (0.0 if n < 7 else 2500.0)) for n in range(1, 10)]
    assert run(m, relaxing) == {} and run(m, [cycle(10, force_mean=26.9e3)]) == {10: ['force_drift']}


def test_tracking_judges_the_measured_against_the_target_amplitude():
    m = Monitor(parse_detectors([{'type': 'tracking'}], 'x'))
    assert run(m, [cycle(n, amp=0.5e-3) for n in range(1, 4)]) == {}      # settling: not judged
    near, far = cycle(4, amp=0.95e-3), cycle(5, amp=0.85e-3)
    assert run(m, [near]) == {} and run(m, [far]) == {5: ['tracking']}
    assert m.events[0].value == pytest.approx(0.15e-3) and m.events[0].units == 'm'


def test_triggers_count_program_or_block_cycles_and_rig_time():
    program, _ = read_program(yaml_text=PROGRAM.replace('threshold: 1 h', 'threshold: 60 s') .replace(
        '      - {type: residual, threshold: 5, action: warn}', '      - {type: cycle_count, threshold: 1000}'))
    m = Monitor(program.all_detectors())
    assert m.on_progress(1, 999, 1003, 50.0) == []
    e, = m.on_progress(1, 1000, 1004, 50.0)
    assert (e.detector, e.action, e.value, e.cycle, e.program_cycle) == ('cycle_count', 'end', 1000, 1000, 1004)
    e, = m.on_progress(1, 1100, 1104, 60.0)
    assert e.detector == 'elapsed_time' and e.units == 's'
    assert m.on_progress(1, 1200, 1204, 70.0) == []                # each once
    assert strongest([]) is None


def test_strongest_action_wins():
    m = Monitor(parse_detectors([{'type': 'residual', 'action': 'record'}, {'type': 'tracking', 'action': 'warn'},
                                 {'type': 'stiffness_change', 'reference': 'model', 'action': 'end'}], 'x'))
    for n in range(1, 4):
        m.on_cycle(cycle(n))
    events = m.on_cycle(cycle(7, k=0.5 * K, residual=1e5, amp=0.5e-3))
    assert [e.action for e in events] == ['warn', 'end'] and strongest(events).action == 'end'


# ---- the failing specimen ------------------------------------------------------------------------------------------
FS = 2000.0


def sine(cycles, f=5.0, amp=1e-3):
    t = np.arange(int(cycles * FS / f)) / FS
    return amp * np.sin(2 * np.pi * f * t)


def specimen(*damage):
    return DamagedSpecimen(LinearSpecimen(K, C, 1 / FS), [DamageSpec(**d) for d in damage], 1 / FS)


def test_the_specimen_counts_its_own_cycles_and_step_equals_run():
    x = sine(20.25)
    a = specimen({'type': 'crack', 'cycle': 7, 'loss': 0.3, 'damping': 5e3})
    b = specimen({'type': 'crack', 'cycle': 7, 'loss': 0.3, 'damping': 5e3})
    fa = a.run(x)
    fb = np.array([b.step(v) for v in x])
    np.testing.assert_allclose(fa, fb, rtol=1e-12, atol=1e-9)
    assert a.cycles == b.cycles == 20.0                # reversals: 40.5 quarter... 40 half cycles after the first
    a.reset()
    assert a.cycles == 0


def test_crack_fatigue_and_slip_laws():
    intact = np.asarray(LinearSpecimen(K, C, 1 / FS).run(sine(20)))
    x = sine(20)
    cracked = specimen({'type': 'crack', 'cycle': 10, 'loss': 0.3}).run(x)
    per = int(FS / 5.0)
    np.testing.assert_allclose(cracked[:9 * per], intact[:9 * per], rtol=1e-12)
    np.testing.assert_allclose(cracked[12 * per:], 0.7 * intact[12 * per:], rtol=1e-9)
    s = specimen({'type': 'fatigue', 'cycle': 0, 'loss': 0.4, 'life': 100, 'exponent': 2})
    assert s.state(50)[0] == pytest.approx(0.1) and s.state(100)[0] == pytest.approx(0.4)
    assert s.state(1000)[0] == 0.95                     # a torn specimen keeps its fixtures' 5 %
    slipped = specimen({'type': 'slip', 'cycle': 5, 'offset': -0.2e-3}).run(x)
    late = slice(8 * per, None)
    np.testing.assert_allclose(slipped[late] - intact[late], K * 0.2e-3, rtol=1e-6)


@pytest.mark.parametrize('damage, field', [
    ({'type': 'melt'}, 'type'), ({'type': 'crack', 'loss': 0.99}, 'loss'), ({'type': 'crack', 'cycle': -1}, 'cycle'),
    ({'type': 'fatigue', 'life': 0}, 'life'), ({'type': 'slip', 'offset': 0.02}, 'offset'),
    ({'type': 'crack', 'damping': -1}, 'damping'), ({'type': 'crack', 'loss': math.inf}, 'loss'),
])
def test_bad_damage_is_refused_naming_the_field(damage, field):
    with pytest.raises(ConfigError, match=rf'sim\.damage\[0\]\.{field}'):
        DamageSpec(**damage).check('sim.damage[0]')


# ---- where a measured cycle lies, across a hold --------------------------------------------------------------------
def test_cycle_position_and_a_resumed_block_runs_only_its_remaining_cycles():
    program, _ = read_program(yaml_text="""
name: two
defaults: {taper_cycles: 1}
blocks:
  - {name: a, waveform: sine, amplitude: 0.5 mm, frequency: 5 Hz, cycles: 4}
  - {name: b, waveform: sine, amplitude: 0.5 mm, frequency: 10 Hz, cycles: 20}
""")
    fs = 1000.0
    r = ProgramRunner(program, fs)
    per_a, per_b = 200, 100
    b0 = 6 * per_a                                      # block b starts after a's 1 + 4 + 1 cycles
    assert r.where.cycle_position(per_a, 2 * per_a) is None   # not generated yet
    r.next_setpoints(b0 + 8 * per_b)                    # ... into block b's 8th cycle (its taper first)
    assert r.where.cycle_position(0, per_a) == (0, 0, False)                      # taper
    assert r.where.cycle_position(2 * per_a, 3 * per_a) == (0, 2, True)
    assert r.where.cycle_position(per_a - 50, 2 * per_a - 50)[2] is False              # starts in the taper
    assert r.where.cycle_position(4 * per_a + 50, 5 * per_a + 50)[2] is True          # ends a lag after the full part
    assert r.where.cycle_position(b0 + 3 * per_b, b0 + 4 * per_b) == (1, 3, True)
    assert r.where.cycle_position(b0 - 50, b0 + 50) is None                        # across two blocks
    assert r.where.cycles_done(b0 + 6 * per_b) == (1, 5, 9)
    r.hold()
    r.next_setpoints(2000)
    # resumed on a new stream, measured up to block b's 6th full cycle: 15 cycles (and tapers) remain
    start = r.sequence + 100
    r.resume_at(start, r.hold_target, measured_sequence=b0 + 6 * per_b + 30)
    x = r.next_setpoints(20000)
    assert r.finished
    assert r.where.cycles_before == {1: 5}
    first_b = int(np.argmax(r.last_block_index == 1)) + start
    n_b = int(np.sum(r.last_block_index == 1))
    assert n_b == (1 + 15 + 1) * per_b
    assert r.where.cycles_done(first_b + 3 * per_b) == (1, 5 + 2, 4 + 5 + 2)
    assert np.max(np.abs(x)) <= 0.5e-3 + 1e-12


def test_a_program_criterion_replaces_the_default_of_its_type():
    program, _ = read_program(yaml_text=PROGRAM)
    got = with_defaults(program.all_detectors(), parse_detectors(list(DEFAULTS), 'default_detectors'))
    expected = [('elapsed_time', -1), ('stiffness_change', 1), ('residual', 1), ('force_drift', -1), ('tracking', -1),
                ('model_fit', -1), ('load_cell', -1)]
    assert [(d.name, d.block) for d in got] == expected


def test_blind_detectors_are_reported_after_two_seconds_and_five_cycles_of_a_periodic_block():
    program, _ = read_program(yaml_text="""
name: blind
blocks:
  - {name: slow, waveform: sine, amplitude: 0.5 mm, frequency: 1 Hz, cycles: 20}
  - {name: rest, waveform: hold, duration: 10 s}
""")
    fs = 1000.0
    r = ProgramRunner(program, fs)
    r.next_setpoints(program.n_samples(fs))
    assert blind_for(r, 4000, 0, fs) == 0.0                # 4 s, 4 cycles: not yet
    assert blind_for(r, 6000, 0, fs) == pytest.approx(6.0)  # 6 s and 6 cycles without a judged cycle
    assert blind_for(r, 6000, 5000, fs) == 0.0             # a cycle judged 1 s ago
    assert blind_for(r, 24000 + 6000, 0, fs) == 0.0        # a hold block has no cycles to judge
    assert Monitor(parse_detectors([{'type': 'residual'}], 'x')).needs_cycles
    assert not Monitor(parse_detectors([{'type': 'cycle_count', 'threshold': 9}], 'x')).needs_cycles
