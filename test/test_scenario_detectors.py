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

"""The detectors' trip delays in cycles and their false trips, on simulated time (rubber_rig.session.scenario):
the simulated specimen is damaged at a load cycle, the element model pairs the cycles, the program's detectors
act, and the rig leaves the program. test_detectors_nodes.py runs the same cases with the nodes as processes on
the wall clock (system tier); there a busy computer adds its own delay to the pipeline's, here it cannot.
"""
import pytest

from rubber_rig.excitation.program import Program
from rubber_rig.rig.options import DamageSpec
from rubber_rig.rig.sim.damage import DamagedSpecimen, sample_at_cycle
from rubber_rig.session.scenario import Scenario

FS, F = 1000.0, 10.0
ONSET = 30            # specimen load cycle at which crack and slip happen
SINE = {'name': 'damage_run',
        'blocks': [{'name': 's10', 'waveform': 'sine', 'frequency': '10 Hz', 'amplitude': '1 mm', 'cycles': 60}]}


def damaged(damage: list, program=SINE, noise: float = 20.0):
    """The outcome of `program` on a specimen with `damage` (DamageSpec mappings), amplitude control on."""
    rig = {'sim': {'force_noise': noise, 'damage': damage}}
    return Scenario(Program.from_dict(program), rig, amplitude_control=True).run()


def delay_cycles(o, onset_cycle: float) -> float:
    """Cycles from the specimen's `onset_cycle` (replayed on the measured displacement) to the first sample the rig
    ran off the program (the hold or end ramp)."""
    i = sample_at_cycle(o.displacement, onset_cycle)
    assert i >= 0, f'the specimen never reached {onset_cycle} cycles'
    departure = o.first_departure(int(o.sequence[i]))
    assert departure is not None, 'the program was never held or stopped'
    return (departure - int(o.sequence[i])) * F / FS


def test_crack_is_held_by_the_residual_detector_within_two_cycles():
    o = damaged([{'type': 'crack', 'cycle': ONSET, 'loss': 0.3, 'damping': 2000.0}])
    kinds = {e.kind: e for _, e in o.detections}
    assert 'residual' in kinds and o.reason.startswith('held by detector'), (o.reason, list(kinds))
    e = kinds['residual']
    assert e.action == 'hold' and e.value > 4 * e.reference
    assert 0 < delay_cycles(o, ONSET) <= 2.0


def test_slip_is_held_by_the_force_drift_detector_within_four_cycles():
    """The default load_cell detector holds a mean-force step back until the second whole cycle after it shows
    whether it creeps back (a slip: cause fixture) or stays flat (a load-cell offset)."""
    program = dict(SINE, detectors=[{'type': 'residual', 'action': 'record'}])
    o = damaged([{'type': 'slip', 'cycle': ONSET, 'offset': 0.3e-3}], program)
    kinds = {e.kind: e for _, e in o.detections}
    assert {'residual', 'force_drift'} <= set(kinds), [e.message for _, e in o.detections]
    drift = kinds['force_drift']
    assert drift.action == 'hold' and drift.message.startswith('[cause fixture/mean_step]'), drift.message
    # 0.3 mm into a ~15 kN/mm joint: the mean force of the first whole cycle after it moves by about -4.4 kN
    assert -5000 < drift.value - drift.reference < -1500, (drift.value, drift.reference)
    assert 0 < delay_cycles(o, ONSET) <= 4.0


def test_fatigue_ends_a_durability_block_at_the_stiffness_criterion_within_two_cycles():
    life, loss = 100.0, 0.4               # 0.4 % of the stiffness lost per cycle
    program = {'name': 'durability',
               'detectors': [{'type': 'stiffness_change', 'threshold': 0.2, 'action': 'end'},
                             {'type': 'residual', 'action': 'record'},
                             {'type': 'force_drift', 'threshold': 0.1, 'action': 'record'}],
               'blocks': [{'name': 'life', 'waveform': 'sine', 'frequency': '10 Hz', 'amplitude': '1 mm',
                           'cycles': 150}]}
    o = damaged([{'type': 'fatigue', 'loss': loss, 'life': life}], program)
    stiff = [e for _, e in o.detections if e.kind == 'stiffness_change']
    assert len(stiff) == 1 and stiff[0].action == 'end' and not o.completed, o.reason
    assert stiff[0].value < 0.8 * stiff[0].reference
    # the criterion is crossed where (1 - D(n)) / (1 - D(n_ref)) = 0.8, D(n) = loss n / life, the reference the
    # median of block cycles 4..6 (the taper adds one specimen cycle before block cycle 1)
    d_ref = DamagedSpecimen(None, [DamageSpec('fatigue', loss=loss, life=life)], 1e-3).state(6.0)[0]
    n_cross = life / loss * (1 - 0.8 * (1 - d_ref))
    # a whole cycle's K_dyn passes the criterion when the cycle's middle does: its end comes 0.5-1.5 cycles after
    # the crossing, and the pipeline (element model, excitation, driver, ramp) adds a fraction of a cycle
    assert 0.5 <= delay_cycles(o, n_cross) <= 2.0


def test_a_clean_program_with_the_default_detectors_trips_none_at_200_newton_noise():
    program = {'name': 'clean', 'blocks': [
        {'name': 'a', 'waveform': 'sine', 'frequency': '10 Hz', 'amplitude': '1 mm', 'cycles': 40},
        {'name': 'b', 'waveform': 'triangle', 'frequency': '2 Hz', 'amplitude': '0.5 mm', 'cycles': 8},
        {'name': 'c', 'waveform': 'sine', 'frequency': '14 Hz', 'amplitude': '0.2 mm', 'cycles': 40}]}
    o = damaged([], program, noise=200.0)
    assert o.completed and o.detections == [], [e.message for _, e in o.detections]


@pytest.mark.parametrize('hold_at', [1.2, 3.33])
def test_no_detector_trips_on_a_clean_program_held_and_resumed(hold_at):
    """A hold and resume is no damage: the specimen relaxes at rest and its first cycles after the resume differ by
    a few percent (the load_cell detector took that for a clipped load cell until this scenario found it)."""
    sc = Scenario(Program.from_dict(SINE), {'sim': {'force_noise': 20.0}}, amplitude_control=True).hold(hold_at, 2.0)
    o = sc.run()
    assert o.completed and o.detections == [], [e.message for _, e in o.detections]


def test_the_same_seed_trips_the_same_detector_events_and_records_the_same_bytes(tmp_path):
    """A scenario whose detectors act (the element model's predictions, the cycle cutter, the detectors, a hold)
    runs twice to the same samples, the same detector events and the same recording, byte for byte: the harness is
    deterministic through the element model and the detectors, not only through the rig
    (benchmarks/scenario_digest.py compares the same between two commits)."""
    runs = []
    for k in range(2):
        path = tmp_path / f'run{k}' / 'crack.mcap'        # (the name is in the file)
        path.parent.mkdir()
        rig = {'sim': {'damage': [{'type': 'crack', 'cycle': ONSET, 'loss': 0.3, 'damping': 2000.0}]}}
        o = Scenario(Program.from_dict(SINE), rig, amplitude_control=True, record=path).run()
        runs.append((o, path.read_bytes()))
    (a, bytes_a), (b, bytes_b) = runs
    assert a.detections and a.reason.startswith('held by detector')
    assert [(t, repr(e)) for t, e in a.detections] == [(t, repr(e)) for t, e in b.detections]
    assert a.events == b.events and a.ended_at == b.ended_at
    assert (a.force.tobytes(), a.setpoint.tobytes()) == (b.force.tobytes(), b.setpoint.tobytes())
    assert len(bytes_a) > 10_000 and bytes_a == bytes_b
