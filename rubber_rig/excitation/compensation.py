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

"""Compensation memory of one run: the amplitude loop's learned command gain and mean offset vs frequency.

Why: the amplitude loop of a block (amplitude.BlockLoop) needs a measured cycle before it can correct, and the
setpoints are generated ahead of the measurement (the excitation node streams them lead_time = 0.5 s ahead so
the driver never starves). At 12-14 Hz with 8 cycles per block that latency is most of the block, so a loop
starting from gain 1 corrects only the last cycles. Commercial controllers keep a compensation table instead:
what earlier blocks learned is the starting point of the next one. This module is that table, kept for one
run of a program (ProgramRunner owns it; nothing persists between runs).

What is stored: per executed periodic block (sine, triangle, square; its latest run) the command gain that gives
the target amplitude (1 / plant gain) and the mean offset that gives the target mean, each averaged over the
last half of the cycles the loop could judge (BlockLoop.learned), together with the block's waveform,
frequency, amplitude and mean. Entries are updated as measured cycles arrive, so a block still being measured
already informs the next one.

Lookup for a new block (deterministic, a pure function of the entries):
- only entries of the same waveform (for square also the same edge slope); sweeps are neither stored nor
  initialised - their frequency changes within the block, so one gain does not describe them;
- entries whose frequencies are within 1 % form one column; per column the entry nearest to the new block
  in amplitude and mean (|ln(a / A)| + |m - M| / A, ties: the most recently updated) is used;
- between columns: linear interpolation in log-frequency; beyond the learned range: linear extrapolation from
  the nearest two columns, but over at most their own log-frequency distance, so the result differs from the
  nearest learned value by no more than the two learned values differ from each other (conservative: two
  close, noisy points cannot produce a large correction); a single column is used as it is.
The caller still caps the gain (gain range, displacement and velocity limits; BlockLoop._cap) and every
setpoint is still checked against the limits.
"""
import math
from dataclasses import dataclass

SAME_FREQUENCY = 0.01        # |ln(f1 / f2)| below this: one column of the table


@dataclass(frozen=True)
class Learned:
    """One entry: what the loop learned in one block. SI units."""

    waveform: str
    frequency: float         # [Hz]
    amplitude: float         # [m] target amplitude of the block
    mean: float              # [m] target mean of the block
    gain: float              # command amplitude gain that reaches the target amplitude
    offset: float            # [m] command mean offset that reaches the target mean
    square_slope: float = 1.0
    order: int = 0           # update counter: later entries win ties


def _compensated(block) -> bool:
    """Periodic blocks whose amplitude one command gain sets (waveform_types: periodic and controlled)."""
    return block.type.periodic and block.type.controlled


def _key(block):
    return block.waveform, round(block.square_slope, 6)          # square_slope is 1 for all but a square


def _interpolate(points, x):
    """Value at x from (x_i, v_i) sorted by x: linear inside, conservative linear extrapolation outside."""
    if len(points) == 1:
        return points[0][1]
    if x <= points[0][0]:
        (xa, va), (xb, vb) = points[0], points[1]
    elif x >= points[-1][0]:
        (xa, va), (xb, vb) = points[-1], points[-2]
    else:
        for (x0, v0), (x1, v1) in zip(points, points[1:], strict=False):
            if x0 <= x <= x1:
                return v0 + (v1 - v0) * (x - x0) / (x1 - x0)
    span = abs(xa - xb)
    d = x - xa
    d = math.copysign(min(abs(d), span), d)   # never further than the two points are apart
    return va + (va - vb) / (xa - xb) * d


class CompensationMemory:
    """Learned gain and mean offset per executed block of one run, and their lookup for a new block."""

    def __init__(self):
        self._entries = {}           # block index -> Learned (latest run of that block)
        self._count = 0

    def learn(self, index: int, block, gain: float, offset: float) -> None:
        """Store (or update) what block `index` learned: the command gain and mean offset [m] it needs."""
        if not _compensated(block) or not (math.isfinite(gain) and gain > 0 and math.isfinite(offset)):
            return
        self._count += 1
        self._entries[index] = Learned(block.waveform, block.frequency, block.amplitude, block.mean, float(gain),
                                       float(offset), _key(block)[1], self._count)

    def entries(self):
        """The stored entries, in block order."""
        return [self._entries[k] for k in sorted(self._entries)]

    def lookup(self, block, exclude: int = None):
        """(gain, offset [m]) to start `block` with, or None when nothing applicable was learned.

        exclude: a block index whose entry is ignored.
        """
        if not _compensated(block) or block.frequency <= 0 or block.amplitude <= 0:
            return None
        key = _key(block)
        cands = sorted((e for k, e in self._entries.items()
                        if k != exclude and (e.waveform, e.square_slope) == key and e.frequency > 0),
                       key=lambda e: (e.frequency, e.order))
        if not cands:
            return None
        columns = []
        for e in cands:
            if columns and math.log(e.frequency / columns[-1][0].frequency) < SAME_FREQUENCY:
                columns[-1].append(e)
            else:
                columns.append([e])

        def distance(e):
            return (abs(math.log(e.amplitude / block.amplitude)) if e.amplitude > 0 else math.inf) \
                + abs(e.mean - block.mean) / block.amplitude

        picks = [min(col, key=lambda e: (distance(e), -e.order)) for col in columns]
        x = math.log(block.frequency)
        gain = _interpolate([(math.log(e.frequency), e.gain) for e in picks], x)
        offset = _interpolate([(math.log(e.frequency), e.offset) for e in picks], x)
        return gain, offset
