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

"""ProgramSession, step by step as the excitation node drives it: a grant, the stream kept `lead` ahead of the
measurement, a hold and a resume on a new grant with the cycles the block had not run, the end once measured.
"""
import numpy as np

from rubber_rig.excitation import Program
from rubber_rig.rig.can.stream import StreamGrant
from rubber_rig.safety import Limits
from rubber_rig.session import ProgramSession

FS = 1000.0
LIFE = Program.from_yaml_text('name: life\nblocks:\n'
                              '  - {name: life, waveform: sine, frequency: 10 Hz, amplitude: 1 mm, cycles: 20}\n')


def session(first=100):
    grant = StreamGrant(stream_id=7, owner='test', first_sequence=first, position=0.0, velocity=0.0)
    return ProgramSession.on_grant(LIFE, FS, Limits(), grant, lead=500, chunk=50, detectors=[])


class Sink:
    """The batches a session hands on, as (first_sequence, setpoints, block, end)."""

    def __init__(self):
        self.batches = []

    def __call__(self, first, x, block, end):
        self.batches.append((first, np.asarray(x, dtype=float), block, end))

    def setpoints(self, start=0):
        return np.concatenate([x for _, x, _, _ in self.batches[start:]])


def test_the_stream_starts_at_the_grant_and_stays_lead_ahead_of_the_measurement():
    s, sink = session(), Sink()
    s.stream(sink)
    assert sink.batches[0][0] == 100 and sink.setpoints().size == 500     # lead ahead of the grant
    assert s.before_stream(50, 50) and not s.before_stream(60, 50)       # samples before the grant: not ours
    s.measured(100, sink.setpoints()[:200])
    assert s.next_sample == 300 and s.elapsed == 0.2
    s.stream(sink)
    assert sink.setpoints().size == 700 and s.runner.sequence == 800


def test_a_resumed_block_runs_the_cycles_it_had_not_run_and_ends_once_measured():
    s, sink = session(), Sink()
    while s.measured_sequence < 1100:   # 10 cycles (10 Hz at 1 kHz) measured in 100-sample batches
        s.stream(sink)
        s.measured(s.measured_sequence, sink.setpoints()[s.measured_sequence - 100:][:100])
    assert s.runner.sequence == 1500 and s.why_not_hold() == ''            # 4 more cycles were queued
    s.hold()
    assert s.held and s.held_at == 1100 and s.why_not_hold() == 'cannot hold: the program is held'
    s.measured(1100, np.zeros(300))                 # the hold ramp: counted nowhere
    assert s.elapsed == 1.0
    s.resume(StreamGrant(stream_id=8, owner='test', first_sequence=5000, position=0.0, velocity=0.0))
    assert (s.stream_id, s.start_sequence, s.next_sample, s.held) == (8, 5000, None, False)
    first = len(sink.batches)
    while not s.measured_to_end:                    # the rig measures everything the session hands on
        s.stream(sink)
        s.measured(s.measured_sequence, sink.setpoints(first)[s.measured_sequence - 5000:])
    moving = np.abs(np.diff(sink.setpoints(first))) > 1e-9
    cycles = moving.sum() / FS * 10
    # by the hold (10 cycles measured) the taper cycle and 9 of the 20 full ones had run: the other 11 run, with a
    # taper in and out 13 (a block restarted from its beginning would run 22)
    assert 12.5 < cycles < 13.5, cycles
    assert s.runner.cycles_before == {0: 9}
    assert s.runner.finished and not s.runner.aborted
