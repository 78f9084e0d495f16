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

"""What a scenario (rubber_rig.session.scenario) ran: the measured samples, how its program ended, the driver's
and the detectors' events, and the questions a test asks of them (where the rig left the program).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np


@dataclass
class Outcome:
    """What a scenario ran: the measured samples (SI units, one entry per sample), how the program ended and the
    driver's events and counters. ``ended_at`` [s] is scenario time from the program's start.
    """

    sequence: np.ndarray
    displacement: np.ndarray
    force: np.ndarray
    setpoint: np.ndarray
    completed: bool
    reason: str
    ended_at: float
    events: list = field(default_factory=list)
    faults: list = field(default_factory=list)
    counters: dict = field(default_factory=dict)
    blocks: list = field(default_factory=list)     # excitation.runner.BlockResult of each block run
    detections: list = field(default_factory=list)  # (scenario time [s], excitation.detectors.Event)
    streamed: list = field(default_factory=list)   # (first sequence, setpoints [m]) of every batch published
    played_end: int = 0         # sequence after the last sample the controller reported it took

    @property
    def final_position(self) -> float:
        return float(self.setpoint[-1]) if self.setpoint.size else math.nan

    def first_departure(self, since: int = 0, tolerance: float = 1.5e-7) -> Optional[int]:
        """The first sample (sequence >= since) whose applied command is not the setpoint streamed for it (by more
        than `tolerance` [m]; a hold or abort ramp took over from the program), or None.
        """
        queued = {}
        for first, x in self.streamed:
            queued.update(zip(range(first, first + len(x)), x.tolist(), strict=True))
        for seq, u in zip(self.sequence.tolist(), self.setpoint.tolist(), strict=True):
            if seq >= since and (seq not in queued or abs(u - queued[seq]) > tolerance):
                return seq
        return None
