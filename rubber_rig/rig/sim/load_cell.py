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

"""Load-cell faults applied to a measured force record: an offset jump, saturation, spikes, a frozen reading.

A stuck load cell is also the simulated controller's own fault (``FaultSpec`` type ``stuck_sensor``, sensor
``force``), which its sensor check turns into an abort; these act on the force channel only. In displacement
control the force reading does not feed back into what the actuator does, so a fault applied to the recorded
force is the force the rig would have reported (the differences: the rig's force limits and the controller's
stuck-sensor check would see the faulty reading).
Used by the detector tests and ``benchmarks/bench_detector_causes.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LOAD_CELL_FAULTS = ('offset_jump', 'saturation', 'spikes', 'stuck')


@dataclass
class LoadCellFault:
    """One load-cell fault from rig time `start` [s] on (SI units).

    offset_jump: the reading steps by `offset` [N] (an amplifier zero jump, a shunt calibration left on);
    saturation: the reading is clipped at +-`limit` [N] (the conditioning amplifier's range);
    spikes: every `period` [s] one sample is off by `offset` [N] with alternating sign (interference); with
            `period` inf, a single spike at `start`;
    stuck:  the reading freezes at its value at `start` (the simulated controller's own ``stuck_sensor`` fault
            does the same, and its sensor check then aborts the run after 100 samples).
    """

    type: str
    start: float = 0.0
    offset: float = 500.0
    limit: float = math.inf
    period: float = math.inf

    def check(self) -> None:
        if self.type not in LOAD_CELL_FAULTS:
            raise ValueError(f"load-cell fault type {self.type!r} is not one of {', '.join(LOAD_CELL_FAULTS)}")
        if not (math.isfinite(self.start) and self.start >= 0):
            raise ValueError(f'load-cell fault start {self.start!r} s: must be finite and >= 0')
        if not math.isfinite(self.offset):
            raise ValueError(f'load-cell fault offset {self.offset!r} N: must be finite')
        if self.type == 'saturation' and not (self.limit > 0 and math.isfinite(self.limit)):
            raise ValueError(f'load-cell saturation limit {self.limit!r} N: must be finite and > 0')
        if not self.period > 0:
            raise ValueError(f'load-cell spike period {self.period!r} s: must be > 0')

    def apply(self, time, force) -> np.ndarray:
        """The force [N] the faulty load cell reports for the true reading `force` at rig times `time` [s]."""
        self.check()
        t, f = np.asarray(time, dtype=float), np.array(force, dtype=float)
        on = t >= self.start
        if self.type == 'offset_jump':
            f[on] += self.offset
        elif self.type == 'stuck':
            index = np.flatnonzero(on)
            if index.size:
                f[index] = f[index[0]]
        elif self.type == 'saturation':
            f[on] = np.clip(f[on], -self.limit, self.limit)
        else:
            index = np.flatnonzero(on)
            if index.size:
                dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
                step = max(1, int(round(self.period / dt))) if math.isfinite(self.period) else index.size
                hits = index[::step]
                f[hits] += self.offset * np.where(np.arange(hits.size) % 2 == 0, 1.0, -1.0)
        return f
