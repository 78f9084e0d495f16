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

"""SetpointStreamer: the one stream-ahead loop of the excitation node and rig.run_program."""
import numpy as np
import pytest

from rubber_rig.excitation import Program, ProgramRunner
from rubber_rig.excitation.streamer import SetpointStreamer
from rubber_rig.safety import Limits

FS = 1000.0
PROGRAM = Program.from_yaml_text(
    'name: two\nblocks:\n'
    '  - {name: a, waveform: sine, frequency: 5 Hz, amplitude: 0.5 mm, cycles: 3, taper_cycles: 1}\n'
    '  - {name: b, waveform: triangle, frequency: 2 Hz, amplitude: 0.3 mm, cycles: 2, taper_cycles: 1}\n')


def runner():
    return ProgramRunner(PROGRAM, FS, Limits())


def test_the_stream_stays_lead_samples_ahead_in_whole_chunks():
    s = SetpointStreamer(runner(), lead=120, chunk=50)
    chunks = list(s.due(0))
    assert [c.first_sequence for c in chunks] == [0, 50, 100]     # 150 >= 0 + 120: the third chunk covers it
    assert all(c.displacement.shape == (50,) and c.block_index.shape == (50,) for c in chunks)
    assert list(s.due(0)) == []                                   # nothing more is due until the measurement moves
    assert [c.first_sequence for c in s.due(31)] == [150]         # 31 + 120 = 151 > 150
    assert s.sequence == 200


def test_chunks_are_the_runners_setpoints_and_the_last_one_says_end():
    s = SetpointStreamer(runner(), lead=40, chunk=64)
    chunks, measured = [], 0
    while not s.finished:
        new = list(s.due(measured))
        assert new, 'a stream that is behind its lead always has a chunk due'
        chunks += new
        measured = s.sequence                     # the rig measured everything sent
    streamed = np.concatenate([c.displacement for c in chunks])
    blocks = np.concatenate([c.block_index for c in chunks])
    whole = runner().next_setpoints(streamed.size)                 # the same program in one call
    np.testing.assert_array_equal(streamed, whole)
    assert [c.end for c in chunks] == [False] * (len(chunks) - 1) + [True]
    n = round(PROGRAM.duration(FS) * FS)
    assert (blocks[:n] >= 0).all() and set(blocks[:n]) == {0, 1} and (np.diff(blocks[:n]) >= 0).all()
    assert (blocks[n:] == -1).all()                               # padding after the end belongs to no block


def test_a_caller_that_stops_iterating_generates_nothing_more():
    s = SetpointStreamer(runner(), lead=500, chunk=50)
    it = s.due(0)
    next(it)
    it.close()                                                    # e.g. the driver refused the chunk
    assert s.sequence == 50


def test_what_happens_between_chunks_shapes_the_next():
    r = runner()
    s = SetpointStreamer(r, lead=1000, chunk=100)
    seen = []
    for c in s.due(0):
        seen.append(c)
        if c.first_sequence == 200:
            r.abort('test')                                       # an abort between two chunks
    assert seen[-1].end and r.aborted
    after = np.concatenate([c.displacement for c in seen[3:]])
    assert (seen[3].block_index == -1).all() and abs(after[-1]) < 1e-9   # the abort ramp ends at rest


@pytest.mark.parametrize('lead,chunk', [(0, 10), (10, 0)])
def test_lead_and_chunk_are_at_least_one_sample(lead, chunk):
    with pytest.raises(ValueError, match='at least one sample'):
        SetpointStreamer(runner(), lead, chunk)
