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
    reserve_after_batch: float = float('nan')   # [s] setpoints queued ahead of the rig once the latest batch was in

    @property
    def name(self) -> str:
        """The owner as a log line names it."""
        return self.grant.owner or 'a local client'

    def refusal(self, first_sequence: int, stream_id) -> str:
        """'' when a batch of stream `stream_id` (None: a local caller's) from first_sequence continues this
        stream, else why it is refused.
        """
        if stream_id is not None and stream_id != self.grant.stream_id:
            return f'stream {stream_id} is not the open stream {self.grant.stream_id} of {self.name}'
        if self.held or self.ended:
            return f'stream {self.grant.stream_id} is {"held" if self.held else "ended"} (open it again to resume)'
        if first_sequence != self.queued_end:
            return (f'batch starts at sample {first_sequence}, the stream continues at {self.queued_end} '
                    '(discontinuous streams are refused)')
        return ''

    def playing(self, expected) -> bool:
        """Setpoints are queued that the rig has not played yet (expected: the next feedback sample, or None).
        A held stream has nothing queued: the controller flushed it and stands at rest until the owner resumes.
        """
        return not self.held and self.queued_end > self.grant.first_sequence and (
            expected is None or expected < self.queued_end)

    def queued(self, first_sequence: int, setpoints: np.ndarray, played_end: int, sample_rate: float) -> None:
        """A batch of setpoints [m] from first_sequence went to the controller, which has played up to played_end
        (the sequence after the last sample it played) at sample_rate [Hz].
        """
        self.queued_end = first_sequence + len(setpoints)
        self.last_queued = float(setpoints[-1])
        self.reserve_after_batch = (self.queued_end - played_end) / sample_rate

    def why_not_reopen(self, owner: str) -> str:
        """'' when `owner` may open the stream again (resume its held or ended stream), else why not."""
        if self.grant.owner != owner:
            return f'the rig is streaming for {self.grant.owner or "another client"} (stream {self.grant.stream_id})'
        if not (self.held or self.ended):
            return f'{owner} already has stream {self.grant.stream_id} open (end it first)'
        return ''

    def lost(self, silent: float, played_end: int, holding: bool, cfg) -> str:
        """'' while an open stream is alive, else why it is lost: paced, no batch for cfg.stream_timeout (silent
        [s] since the last one) while the rig has less than cfg.stream_timeout of setpoints left to play
        (played_end: the sequence after the last sample it played, at cfg.sample_rate); or the controller played
        all it had and holds before the owner's last batch.

        Silence alone is not loss: an owner that streams lead_time ahead and stalls (a busy computer delays its
        executor 0.3-0.8 s) has setpoints queued for the whole stall, and the rig plays them without noticing.
        The stream is lost when the silence starts to eat the reserve a smooth stop needs, stream_timeout of
        setpoints, so a dead owner is still caught before the rig runs dry (within lead_time - stream_timeout of
        its last batch, or by the driver's owner watch on its heartbeat, whichever is first).
        """
        reserve = (self.queued_end - played_end) / cfg.sample_rate
        if cfg.paced and silent > cfg.stream_timeout and reserve < cfg.stream_timeout:
            # the reserve its last batch left says which side was late: about lead_time, the owner then stalled
            # for the whole silence; much less, it was already behind (late batches, or a slow way to the driver)
            return (f'no setpoints from {self.grant.owner or "the stream owner"} for {silent:.3f} s '
                    f'({max(reserve, 0.0) * 1e3:.0f} ms of setpoints left; its last batch had left '
                    f'{self.reserve_after_batch * 1e3:.0f} ms)')
        if self.queued_end > self.grant.first_sequence and played_end >= self.queued_end and holding:
            return f'the rig ran out of setpoints at sample {self.queued_end} before the end of the stream'
        return ''
