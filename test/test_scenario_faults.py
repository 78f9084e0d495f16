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

"""The fault matrix's logic on simulated time (rubber_rig.session.scenario): faults of the simulated controller,
foreign setpoints, an operator's abort and a limit tightened at run time. Each ends at rest inside the limits,
says why, counts every lost sample once, and the next program runs on the same rig after a reset.
test_fault_matrix.py runs them with the nodes as processes and DDS between them (system tier): the wiring.
"""
import numpy as np
import pytest

from rubber_rig.excitation.program import Program
from rubber_rig.rig.can.gate import MUTE_AFTER
from rubber_rig.rig.can.protocol import FAULT_BUS, FAULT_DISPLACEMENT_LIMIT, FAULT_SENSOR, FAULT_WATCHDOG
from rubber_rig.rig.config import RigConfig
from rubber_rig.session.scenario import Scenario

LIMITS = RigConfig().limits


def program(blocks):
    return Program.from_dict({'name': 'case', 'blocks': blocks})


FAST_SINE = program([{'waveform': 'sine', 'frequency': '20 Hz', 'amplitude': '0.5 mm', 'cycles': 80}])
SLOW_TRIANGLE = program([{'waveform': 'triangle', 'frequency': '0.5 Hz', 'amplitude': '1 mm', 'cycles': 3}])
SMALL_SINE = program([{'waveform': 'sine', 'frequency': '2 Hz', 'amplitude': '0.01 mm', 'cycles': 20}])
NEXT = program([{'waveform': 'sine', 'frequency': '5 Hz', 'amplitude': '0.5 mm', 'cycles': 5}])

SIM_FAULTS = {
    # name: (fault 1.2 s into the rig's time, program, fault bit); each is over before the rig has ramped down
    'silent_controller_fast': ({'type': 'silent_controller', 'duration': 0.35}, FAST_SINE, FAULT_WATCHDOG),
    'stuck_displacement_slow': ({'type': 'stuck_sensor', 'sensor': 'displacement', 'duration': 0.4},
                                SLOW_TRIANGLE, FAULT_SENSOR),
    'stuck_force_small': ({'type': 'stuck_sensor', 'sensor': 'force', 'duration': 0.2}, SMALL_SINE, FAULT_SENSOR),
    'corrupt_frames_fast': ({'type': 'corrupt', 'duration': 0.2, 'probability': 0.5}, FAST_SINE, FAULT_BUS),
}


def at_rest_inside(o, limits=LIMITS, rest=0.0):
    """At rest at `rest` [m] and never outside the limits. The last sample received may be a few samples before the
    ramp's end (frames lost on the bus at the very end): within 2 um of rest, where the ramp creeps in."""
    u = o.setpoint
    inside = limits.displacement_min <= u.min() and u.max() <= limits.displacement_max
    return abs(o.final_position - rest) < 2e-6 and inside


def missing_samples(o) -> int:
    """Samples the controller took (from the first received to the last it reported) that the record lacks."""
    return int(o.played_end - o.sequence[0] - np.unique(o.sequence).size)


@pytest.mark.parametrize('name', sorted(SIM_FAULTS))
def test_simulated_rig_faults_end_safely_count_their_loss_and_the_next_program_runs(name):
    spec, prog, bit = SIM_FAULTS[name]
    sc = Scenario(prog, {'sim': {'faults': [dict(spec, start=1.2)]}})
    o = sc.run()
    assert not o.completed and o.reason.startswith('rig fault'), o.reason
    assert sc.driver.faults & bit, (sc.driver.faults, o.faults)
    assert at_rest_inside(o)
    # every sample the bus lost is counted by the driver, and that count is what the record is missing
    assert o.counters['frames_lost'] == missing_samples(o), (o.counters, missing_samples(o))
    if name.startswith('corrupt'):
        assert missing_samples(o) > 0
    sc.wait(1.0)                      # the operator looks, the fault's window ends, then the reset
    nxt = sc.run(program=NEXT)        # the operator resets; the same rig runs the next program
    assert nxt.completed and not nxt.faults, (nxt.reason, nxt.faults)


def test_foreign_setpoints_with_the_stream_id_copied_are_refused_and_counted():
    """Another process publishes the owner's stream id and next sequence at +3 mm, on a channel of its own and
    under the owner's name: refused, counted, no fault, and the program completes inside the envelope."""
    sc = Scenario(FAST_SINE).foreign(1.0, '/intruder', Scenario.OWNER, 3e-3, n=3)
    o = sc.run()
    assert [v.action for v in sc.refusals] == ['refused'] * 3
    assert all('not the stream owner' in v.why for v in sc.refusals), [v.why for v in sc.refusals]
    assert o.completed and not o.faults and o.counters['setpoints_refused'] == 150
    assert np.abs(o.setpoint).max() <= 0.5e-3 + 1e-9


def test_a_flood_on_the_owners_channel_never_mutes_the_owner():
    flood = 5 * MUTE_AFTER
    sc = Scenario(FAST_SINE).foreign(1.0, Scenario.OWNER, '/forger', 3e-3, n=flood)
    o = sc.run()
    assert {v.action for v in sc.refusals} == {'refused'} and len(sc.refusals) == flood
    assert not sc.gate.muted(Scenario.OWNER)
    assert o.completed and not o.faults and np.abs(o.setpoint).max() <= 0.5e-3 + 1e-9


def test_a_driver_abort_mid_program_ends_it_and_ramps_to_rest_inside_the_limits():
    sc = Scenario(FAST_SINE).at(1.5, lambda s: s.driver.abort('operator: rig_driver/abort'))
    o = sc.run()
    assert not o.completed and 'the rig stopped the program' in o.reason, o.reason
    assert at_rest_inside(o) and o.ended_at < 1.6
    assert sc.run(program=NEXT).completed


def test_limits_tightened_at_run_time_apply_at_once_and_the_rig_ramps_into_them():
    tight = RigConfig.from_dict({'limits': {'displacement_min': -0.3e-3, 'displacement_max': 0.3e-3}}).limits
    sc = Scenario(FAST_SINE).at(1.0, lambda s: s.driver.set_limits(tight))
    o = sc.run()
    assert not o.completed and sc.driver.faults & FAULT_DISPLACEMENT_LIMIT, (o.reason, o.faults)
    changed = int(np.searchsorted(o.sequence, o.sequence[0] + 1000))
    # from the change on the rig only comes closer to the new range, and ends at rest inside it
    assert np.abs(o.setpoint[changed:]).max() <= max(abs(o.setpoint[changed]), 0.3e-3) + 1e-9
    assert at_rest_inside(o)
    assert np.abs(np.diff(o.setpoint, 2)).max() * 1e6 <= 20.0 + 1e-6    # the ramp's acceleration, no step
