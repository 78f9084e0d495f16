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

"""Stream-ahead of a test program: the setpoints a rig needs next, a fixed lead ahead of the measurement.

A rig queues setpoints and applies one per sample; the program's generator (:class:`.runner.ProgramRunner`)
needs the measurement for amplitude control. :class:`SetpointStreamer` keeps the generated setpoints ``lead``
samples ahead of the last measured sample, in chunks of ``chunk`` samples: far enough that the queue never
runs dry between two deliveries of the bus or the network, near enough that the amplitude loop reacts within
``lead`` samples. The excitation node publishes its chunks as SetpointBatch messages; ``rig.run_program``
queues them on the driver directly. Time is the sample index: nothing here reads a clock.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np

from .runner import ProgramRunner


@dataclass(frozen=True)
class SetpointChunk:
    """Consecutive setpoints of a program.

    first_sequence: sequence number of the first setpoint; displacement [m], shape (n,); block_index: program
    block of each setpoint, shape (n,), -1 outside the blocks (approach or abort ramp, after the end);
    end: these are the program's last setpoints.
    """

    first_sequence: int
    displacement: np.ndarray
    block_index: np.ndarray
    end: bool

    @property
    def block(self) -> int:
        """Block of the first setpoint (-1 for an empty chunk): what a batch message carries."""
        return int(self.block_index[0]) if self.block_index.size else -1


class SetpointStreamer:
    """Keeps ``runner``'s setpoints ``lead`` samples [>= 1] ahead of the measurement, in chunks of ``chunk``."""

    def __init__(self, runner: ProgramRunner, lead: int, chunk: int):
        if int(lead) < 1 or int(chunk) < 1:
            raise ValueError(f'lead ({lead}) and chunk ({chunk}) must be at least one sample')
        self.runner, self.lead, self.chunk = runner, int(lead), int(chunk)

    @property
    def sequence(self) -> int:
        """Sequence number of the next setpoint to generate."""
        return self.runner.sequence

    @property
    def finished(self) -> bool:
        return self.runner.finished

    def due(self, measured: int) -> Iterator[SetpointChunk]:
        """The chunks that bring the stream to ``measured + lead``; ``measured`` is the sequence after the last
        measured sample. A generator: a caller that cannot queue a chunk stops iterating and nothing more is
        generated, and what the caller does between two chunks (feed a measurement, abort) shapes the next.
        """
        r = self.runner
        while not r.finished and r.sequence < measured + self.lead:
            first = r.sequence
            x = r.next_setpoints(self.chunk)
            yield SetpointChunk(first, x, r.last_block_index, r.finished)
