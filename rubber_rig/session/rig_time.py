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

"""The rig clock of a sample sequence: when the rig measured (or will apply) sample n."""
from __future__ import annotations


class RigTime:
    """Rig time [s] of any sample sequence, from the latest sample batch's stamp plus the samples between.

    A setpoint batch is stamped with the time it is for, as a sample batch with the time it was measured; before
    any sample has arrived, the first setpoint asked about applies `now` (a new stream starts with its first
    batch).
    """

    def __init__(self):
        self.base: tuple[int, float] | None = None    # (sequence, rig time [s]) of the latest sample batch

    def observe(self, first_sequence: int, stamp: float) -> None:
        """A sample batch starting at `first_sequence` was measured at rig time `stamp` [s]."""
        self.base = (int(first_sequence), float(stamp))

    def of(self, sequence: int, dt: float, now: float) -> float:
        """Rig time [s] of sample `sequence` at `dt` [s] per sample; `now` [s] sets the base if none is known."""
        if self.base is None:
            self.base = (int(sequence), float(now))
        first, t0 = self.base
        return t0 + (sequence - first) * dt
