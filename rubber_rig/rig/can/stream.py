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

"""What the host driver hands out: measured sample blocks, status snapshots, stream grants and refusals."""
from dataclasses import dataclass, field
from typing import List

import numpy as np


@dataclass
class SampleBlock:
    """Consecutive measured samples: sample i has sequence first_sequence + i and was taken at
    t0 + i * sample_period (t0: bus timestamp of the first sample's frame [s]). SI units. `setpoint` is the
    command the controller applied (the host setpoint, or its own ramp after an abort). frames_lost: samples
    lost on the bus just before this block.
    """

    first_sequence: int
    t0: float
    sample_period: float
    displacement: np.ndarray
    force: np.ndarray
    setpoint: np.ndarray
    temperature: float
    status_flags: int
    frames_lost: int

    def __len__(self):
        return int(self.displacement.size)

    @property
    def sequence(self) -> np.ndarray:
        return np.arange(self.first_sequence, self.first_sequence + len(self), dtype=np.int64)


@dataclass
class DriverStatus:
    """Snapshot of the driver (the fields of msg_defs/RigStatus, which the node fills from it; faults is the
    FAULT_* bit mask).
    """

    state: str
    faults: int
    fault_messages: List[str]
    sample_rate: float
    samples_received: int
    frames_lost: int
    frames_late: int
    frames_malformed: int
    frames_unknown: int
    temperature: float
    controller_state: str
    controller_faults: int
    controller_sequence: int
    setpoints_sent: int
    limits: object = None
    extra: dict = field(default_factory=dict)


class StreamRefused(ValueError):
    """A stream could not be opened or a batch was refused; the message says why."""


@dataclass
class StreamGrant:
    """The right to command the rig: setpoints of stream `stream_id` start at first_sequence and must continue
    from `position` [m] (the command the rig holds) at `velocity` [m/s].
    """

    stream_id: int
    owner: str
    first_sequence: int
    position: float
    velocity: float


@dataclass
class GrantedStream:
    """A granted stream as the driver keeps it: the grant, how far it is queued, and whether it is held."""

    grant: StreamGrant
    queued_end: int             # sequence after the last queued setpoint
    last_queued: float          # last queued setpoint [m] (the true continuation of the applied command)
    last_rx_wall: float         # wall time of the latest batch
    ended: bool = False         # the owner sent its last batch: running dry is the end, not a loss
    batches: int = 0            # batches accepted (keep-alives included): 0 = granted, nothing sent yet
    held: bool = False          # stopped by a hold: the owner keeps the rig and re-opens to resume
