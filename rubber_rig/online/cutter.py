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

"""CycleCutter: the element model's measured-and-predicted samples cut into cycles block by block, ROS-free.

Setpoints (which carry the program block index) and samples travel on different topics, so the setpoints of a
batch can arrive after its samples: a batch waits for them while a stream is open, at most ``wait`` seconds on
the injected clock (an unpaced rig runs many seconds of samples per second, so rig time cannot say how long a
message is late). Samples after the stream's last batch (a rig holding or at rest), or with no setpoints for
``wait`` (a rig moved by something else), belong to no block (-1) and go at once. The element_model node feeds
it from its subscriptions; a scenario (rubber_rig.session.scenario) from its simulated topics.
"""
from __future__ import annotations

import math
import time
from collections import deque
from typing import Callable, NamedTuple

import numpy as np

from .cycles import CyclePairer, PairedCycle
from .predictor import BlockIndex

SETPOINT_WAIT = 1.0   # [s] a sample batch waits at most this long for the setpoints that say its block


class CutCycle(NamedTuple):
    """A finished cycle of program block ``block``; ``t_end`` [s] the stamp of its last sample."""

    cycle: PairedCycle
    block: int
    t_end: float


def finite_runs(*arrays) -> list[tuple[int, int]]:
    """[(start, stop)] of the runs of samples finite in every array (all of them when there is nothing to skip)."""
    good = np.logical_and.reduce([np.isfinite(a) for a in arrays])
    if good.all():
        return [(0, len(good))] if len(good) else []
    edges = np.flatnonzero(np.diff(np.concatenate([[False], good, [False]]).astype(np.int8)))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=False))


class CycleCutter:
    """Cycles of measured (``f``) and predicted force against displacement, block by block (module docstring).

    hysteresis, min_amplitude [m]: the CyclePairer's; clock: seconds [s] the waits are judged on.
    """

    def __init__(self, min_amplitude: float, hysteresis: float = None, wait: float = SETPOINT_WAIT,
                 clock: Callable[[], float] = time.monotonic):
        self._pairer_args = dict(min_amplitude=min_amplitude)
        if hysteresis is not None:
            self._pairer_args['hysteresis'] = hysteresis
        self.pairer = CyclePairer(**self._pairer_args)
        self.blocks = BlockIndex()
        self.wait, self._clock = float(wait), clock
        self._queue = deque()             # sample batches waiting for the setpoints that say their block
        self._setpoints_at = -math.inf    # clock() of the latest setpoint batch
        self.errors = 0                   # cycles the metrics could not evaluate (detection restarted)
        self.error_messages: list[str] = []   # why, since the caller last took them

    def setpoints(self, first_sequence: int, n: int, block_index: int, end_of_stream: bool) -> None:
        """A setpoint batch: its samples belong to ``block_index`` (an empty one only keeps the stream alive)."""
        if n:
            self.blocks.add(first_sequence, n, block_index)
        self.blocks.ended = end_of_stream
        self._setpoints_at = self._clock()

    def samples(self, first_sequence: int, dt: float, x, f, predicted, t0: float) -> None:
        """A sample batch: displacement x [m], measured f and predicted force [N], its first sample at t0 [s]."""
        self._queue.append((first_sequence, dt, x, f, predicted, t0, self._clock()))

    @property
    def waiting(self) -> int:
        """Sample batches waiting for their block (cycles() may release them)."""
        return len(self._queue)

    def restart(self) -> None:
        """A restarted driver: drop what waits and start the cycle detection afresh."""
        self._queue.clear()
        self.pairer = CyclePairer(**self._pairer_args)

    def cycles(self) -> list[CutCycle]:
        """The cycles finished by the batches whose block is known (or no longer worth waiting for)."""
        out = []
        while self._queue:
            first, dt, x, f, predicted, t0, arrived = self._queue[0]
            now = self._clock()
            if not self.blocks.covered(first + len(x) - 1) and not self.blocks.ended \
                    and now - arrived < self.wait and now - self._setpoints_at < self.wait:
                break
            self._queue.popleft()
            for lo, hi, block in self.blocks.segments(first, len(x)):
                for a, b in finite_runs(x[lo:hi], f[lo:hi], predicted[lo:hi]):
                    # a run after skipped samples starts at a later sequence: the pairer restarts its detector
                    start = first + lo + a
                    out.extend(CutCycle(c, block, t0 + (c.end_sequence - first) * dt)
                               for c in self._feed(start, dt, x[lo + a:lo + b], f[lo + a:lo + b],
                                                   predicted[lo + a:lo + b], block))
        return out

    def _feed(self, start, dt, x, f, predicted, block) -> list[PairedCycle]:
        try:
            return self.pairer.feed(start, dt, x, f, predicted, block)
        except ValueError as exc:   # a cycle the harmonic fit cannot evaluate: say so, start the detection afresh
            self.errors += 1
            self.error_messages.append(f'cycle metrics at sequence {start}: {exc}; cycle detection restarts '
                                       f'({self.errors} so far)')
            self.pairer = CyclePairer(**self._pairer_args)
            return []
