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

"""Sample blocks from the driver gathered into batches of at least a given size, for publishing.

Blocks are never split: the stamp of a batch (t0) is the real bus time of its first sample. A gap (samples
lost on the bus) ends a batch, so the next one starts after it; a batch whose first sample has waited longer
than the allowed delay (the stream paused: program end, an abort's ramp done) is due as it is.
"""
import time

import numpy as np

from .stream import SampleBlock


class SampleBatcher:
    """Gathers contiguous SampleBlocks; clock: the time [s] a batch's first block arrived is judged by."""

    def __init__(self, clock=time.monotonic):
        self._clock = clock
        self._blocks: list = []
        self._count = 0            # samples gathered
        self._since = 0.0          # clock time the first gathered block arrived

    def add(self, block: SampleBlock, size: int) -> list:
        """Gather `block`; the batches (SampleBlocks) complete now: the one a gap before `block` ended, and the
        one that reached `size` samples.
        """
        done = []
        last = self._blocks[-1] if self._blocks else None
        if last is not None and block.first_sequence != last.first_sequence + len(last):
            done.append(self.take())   # samples lost on the bus: the next batch starts after the gap
        if not self._blocks:
            self._since = self._clock()
        self._blocks.append(block)
        self._count += len(block)
        if self._count >= size:
            done.append(self.take())
        return done

    def due(self, max_delay: float):
        """The partial batch whose first sample has waited more than max_delay [s], or None."""
        if self._count and self._clock() - self._since > max_delay:
            return self.take()
        return None

    def take(self):
        """Everything gathered as one SampleBlock (None if nothing is): the first block's sequence and time, the
        last block's temperature and status flags, the samples lost before any of them.
        """
        blocks, self._blocks, self._count = self._blocks, [], 0
        if not blocks:
            return None
        first, last = blocks[0], blocks[-1]
        cat = {k: np.concatenate([getattr(b, k) for b in blocks]) for k in ('displacement', 'force', 'setpoint')}
        return SampleBlock(first.first_sequence, first.t0, first.sample_period, cat['displacement'], cat['force'],
                           cat['setpoint'], last.temperature, last.status_flags,
                           sum(int(b.frames_lost) for b in blocks))
