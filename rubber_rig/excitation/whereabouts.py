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

"""Where a sample is in the program: the block and phase of a setpoint's sequence number, the cycle a measured
cycle belongs to, the cycles done at a sample (counted across holds). A ProgramRunner records here what it
generated, segment by segment (``record``), and the cycles a resumed block had run (``cycles_before``); the
program session, the detectors and the runner's own measurement ask it (``ProgramRunner.where``).
"""
import bisect
import math

import numpy as np


class Whereabouts:
    """The generation record of one run of `program` at `fs` [Hz], and the questions about sequence numbers it
    answers. A segment is [seq0, seq1, block, local0 (block sample of seq0), amplitude loop or None].
    """

    def __init__(self, program, fs: float):
        self.program, self.fs = program, float(fs)
        self.segments: list = []
        self.seg_starts: list = []
        self.cycles_before: dict = {}       # block index -> full cycles run before its latest resume

    def record(self, seq0: int, m: int, b: int, local0: int, loop) -> None:
        """Setpoints seq0 .. seq0 + m - 1 were generated for block b from its sample local0 (one segment with the
        previous one if they continue it).
        """
        last = self.segments[-1] if self.segments else None
        if last and last[1] == seq0 and last[2] == b and last[4] is loop and last[3] + (last[1] - last[0]) == local0:
            last[1] += m
            return
        self.segments.append([seq0, seq0 + m, b, local0, loop])
        self.seg_starts.append(seq0)

    def overlapping(self, s0: int, s1: int):
        """The segments holding any of the sequences s0 .. s1 - 1, in order."""
        j = max(bisect.bisect_right(self.seg_starts, s0) - 1, 0)
        while j < len(self.segments) and self.segments[j][0] < s1:
            yield self.segments[j]
            j += 1

    def locate(self, sequence: int):
        """(block index, phase [cycles since the block's start, tapers included; seconds for hold/ramp blocks
        times its frequency = 0]) of the setpoint with this sequence number, or None outside program blocks.
        """
        segment = self._segment_of(sequence)
        if segment is None:
            return None
        seq0, _, b, local0, _ = segment
        blk = self.program.blocks[b]
        t = (local0 + sequence - seq0) / self.fs
        return b, float(blk.phase(np.array(t))) if blk.oscillating else 0.0

    def _segment_of(self, sequence: int):
        """The generated segment [seq0, seq1, block, local0, loop] holding the setpoint `sequence`, or None."""
        if sequence is None:
            return None
        j = bisect.bisect_right(self.seg_starts, sequence) - 1
        if j < 0:
            return None
        segment = self.segments[j]
        return segment if segment[0] <= sequence < segment[1] else None

    def program_position(self, sequence: int):
        """(block, samples of the block run) when the rig has run the setpoints before ``sequence`` (the sample
        after the last one it ran on the program), or None when the setpoint before it is not a program sample
        (an approach or hold ramp, nothing generated yet).
        """
        segment = self._segment_of(int(sequence) - 1)
        if segment is None:
            return None
        seq0, _, b, local0, _ = segment
        return b, local0 + int(sequence) - seq0

    def cycle_position(self, start: int, end: int):
        """Where the measured cycle of samples start..end-1 lies: (block, full-amplitude cycle number counted
        across holds, steady), or None when it is not inside one periodic block. Steady: inside the block's
        full-amplitude part (tapers excluded; a quarter cycle of slack at its end for the actuator's lag).
        """
        a, z = self.locate(start), self.locate(end - 1)
        if a is None or z is None or a[0] != z[0]:
            return None
        b = a[0]
        blk = self.program.blocks[b]
        if not blk.oscillating:
            return None
        full = blk.total_cycles - blk.taper_cycles
        # the actuator lags: a measured cycle ends up to a quarter cycle after the full part, but never starts
        # before the taper has ended (one that does carries taper, at a lower amplitude)
        steady = a[1] >= blk.taper_cycles and z[1] <= full + 0.25
        number = int(math.floor(z[1] - blk.taper_cycles + 0.25)) + self.cycles_before.get(b, 0)
        return b, max(number, 0), steady

    def cycles_done(self, sequence: int) -> tuple[int, int, int]:
        """(block, its full-amplitude cycles done, the program's full-amplitude cycles done) at `sequence`
        (counted across holds); block -1 before the first program sample.
        """
        located = self.locate(sequence)
        if located is None:
            return -1, 0, 0
        b, phase = located
        blk = self.program.blocks[b]
        done = 0
        if blk.periodic:
            done = min(max(int(math.floor(phase - blk.taper_cycles)), 0), blk.cycles) + self.cycles_before.get(b, 0)
        before = sum(blocks.cycles + self.cycles_before.get(i, 0) for i, blocks in enumerate(self.program.blocks[:b])
                     if blocks.periodic)
        return b, done, before + done
