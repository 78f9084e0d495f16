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

"""Issue 34 item 4, stream loss that a busy computer cannot fake, in the scenario harness on simulated time: the
excitation stalled 0.5-0.8 s anywhere in a program, while the sample path is late as it is on a loaded computer,
costs latency and never the program; a dead excitation still ends it at rest within the stated time. And the rule
that makes it so (session.rig_pace.RigPace, ProgramSession.ahead_of) on its own.
"""
import numpy as np
import pytest

from rubber_rig.excitation.program import Program
from rubber_rig.rig.can.protocol import cycle_time
from rubber_rig.rig.can.stream import StreamGrant
from rubber_rig.rig.config import RigConfig
from rubber_rig.safety import Limits
from rubber_rig.session.program_session import LEAD_TIME, ProgramSession
from rubber_rig.session.rig_pace import MAX_STAMP_LAG, RigPace
from rubber_rig.session.scenario import Scenario

from support.scenario import DURABILITY, FS, STREAM_PERIOD, STREAM_TIMEOUT, at_rest_inside_limits, full_cycles

SAMPLES_LATE = 0.1        # [s] the sample path's delay around a stall (the soak's 87 ms case needed ~0.11 s)
SETPOINTS_LATE = 0.02     # [s] the setpoints' way to the driver, all the time


def loaded(scenario: Scenario, at: float, stall: float) -> Scenario:
    """A loaded computer around a stall at `at` [s]: the samples reach the excitation SAMPLES_LATE late from 1 s
    before it until 0.5 s after it, the setpoints reach the driver SETPOINTS_LATE late throughout."""
    start = max(0.0, at - 1.0)
    return scenario.delay('samples', SAMPLES_LATE, start, at + stall + 0.5 - start).delay('setpoints', SETPOINTS_LATE)


@pytest.mark.parametrize('stall', [0.5, 0.8])
@pytest.mark.parametrize('at', [0.05, 1.03, 2.5, 3.77, 6.2])
def test_an_excitation_stalled_half_to_most_of_a_second_on_a_loaded_computer_does_not_end_its_program(at, stall):
    """At 0.05 s (the approach), 1.03 s (the taper), 2.5 s and 3.77 s (mid-block), 6.2 s (the second block): every
    cycle runs, no sample is lost, no fault. Before the stream was kept ahead of the rig's pace, a 0.5 s stall with
    the samples 0.05 s late ended the program ('no setpoints ... for 0.502 s'), as in the soak."""
    o = loaded(Scenario(DURABILITY).stall('excitation', at, stall), at, stall).run()
    assert o.completed and not o.faults, (o.reason, o.faults)
    assert full_cycles(o) == 60 and np.all(np.diff(o.sequence) == 1)
    assert [b.cycles_measured for b in o.blocks] == [60, 5]


@pytest.mark.parametrize('stall', [0.5, 0.8])
def test_a_sample_path_late_for_the_whole_program_is_read_from_the_stamps(stall):
    """A loaded computer for seconds on end (the soak's second suite): every sample batch 0.5 s late, so the arrival
    times alone never see the rig's pace; the batches' stamps do (rig_pace.MAX_STAMP_LAG 1 s: with 0.25 s this
    stall lost the stream, 'no setpoints ... for 0.352 s (140 ms of setpoints left)')."""
    scenario = Scenario(DURABILITY).delay('samples', 0.5).delay('setpoints', SETPOINTS_LATE)
    o = scenario.stall('excitation', 3.77, stall).run()
    assert o.completed and not o.faults, (o.reason, o.faults)
    assert full_cycles(o) == 60


@pytest.mark.parametrize('at', [1.03, 3.77])
def test_a_dead_excitation_on_a_loaded_computer_still_ends_its_program_at_rest_within_the_stated_time(at):
    """Dead at `at`: the driver calls the stream lost once less than stream_timeout of setpoints is left, lead_time
    - stream_timeout after the last batch that reached it (one stream period before the death at most, and the
    setpoints' delay after it; ControllerStatus tells where the rig plays, one status period old at most)."""
    o = loaded(Scenario(DURABILITY).stall('excitation', at), at, 10.0).run()
    assert not o.completed and 'setpoint stream lost' in o.reason, o.reason
    detected = o.ended_at - at
    earliest = LEAD_TIME - STREAM_TIMEOUT - STREAM_PERIOD
    latest = LEAD_TIME - STREAM_TIMEOUT + SETPOINTS_LATE + 2 * cycle_time('ControllerStatus')
    assert earliest <= detected <= latest, detected
    assert at_rest_inside_limits(o, RigConfig().limits)
    assert (np.abs(np.diff(o.setpoint, 2)) * FS * FS).max() <= 20.0 + 1e-6     # the ramp (RAMP_ACCEL), no step


# -- the rule ------------------------------------------------------------------------------------------------------
def test_the_pace_is_the_fastest_batchs_and_a_late_backlog_does_not_move_it_back():
    pace = RigPace(FS)
    assert pace.playing(10.0) is None
    for k in range(10):                       # batches of 10 samples, 3 ms on their way
        pace.observe(10 * (k + 1), 0.010 * (k + 1) + 0.003)
    assert pace.playing(0.103) == 100
    # a stall: the next 50 batches arrive together 0.6 s later; the rig played on at its pace meanwhile
    for k in range(10, 60):
        pace.observe(10 * (k + 1), 0.703)
    assert pace.playing(0.703) == 700
    assert pace.playing(6.0) is None          # nothing vouched for the pace within the window (5 s)


def test_a_credible_stamp_removes_the_paths_lag_and_another_clock_is_ignored():
    pace = RigPace(FS)
    pace.observe(100, 0.150, stamp=0.099)     # sample 99 measured at 0.099 s, arrived 51 ms later
    assert pace.playing(0.150) == 150
    other = RigPace(FS)
    other.observe(100, 0.150, stamp=0.099 - 2 * MAX_STAMP_LAG)   # a clock off by more than the credible lag
    assert other.playing(0.150) == 100
    ahead = RigPace(FS)
    ahead.observe(100, 0.150, stamp=0.2)      # measured after it arrived: another clock
    assert ahead.playing(0.150) == 100


def test_a_session_streams_lead_ahead_of_the_rigs_pace_and_at_most_one_lead_past_the_measurement():
    program = Program.from_dict({'name': 'p', 'blocks': [{'waveform': 'sine', 'amplitude': '1 mm',
                                                          'frequency': '10 Hz', 'cycles': 100}]})
    grant = StreamGrant(1, '/x', 1000, 0.0, 0.0)
    s = ProgramSession.on_grant(program, FS, Limits(), grant, 700, 50)
    assert s.ahead_of(5.0) == 1000                   # no batch yet: the stream's start
    s.measured(1000, np.zeros(100), now=5.2)         # 100 samples arrived at 5.2 s
    assert s.ahead_of() == 1100 and s.ahead_of(5.2) == 1100
    assert s.ahead_of(5.5) == 1400                   # 0.3 s later the rig plays sample 1400
    assert s.ahead_of(9.0) == 1100 + 700             # a rig that stopped its pace: one lead of latency at most
    sent = []
    s.stream(lambda first, x, block, end: sent.append((first, len(x))), now=5.5)
    assert sum(n for _, n in sent) >= 1400 + 700 - 1000 and s.runner.sequence - (1400 + 700) < 50
