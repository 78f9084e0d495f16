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
and the detectors' events, and the questions a test asks of them (where the rig left the program); and the
records it writes to MCAP as the recorder node writes the topics (stamped with scenario time).
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


NS = '/scenario'        # the namespace of a scenario's recorded topics


def header(t: float) -> dict:
    """A std_msgs/Header stamped `t` [s] (scenario time: the same run, the same stamps)."""
    ns = int(round(t * 1e9))
    return {'stamp': {'sec': ns // 1_000_000_000, 'nanosec': ns % 1_000_000_000}, 'frame_id': ''}


def sample_batch_record(batch) -> tuple[str, str, dict]:
    """(topic, type, fields) of a rig.can.stream.SampleBlock as rig_driver publishes it (msg_defs/RigSampleBatch)."""
    return f'{NS}/samples', 'msg_defs/msg/RigSampleBatch', {
        'header': header(batch.t0), 'first_sequence': batch.first_sequence, 'sample_period': batch.sample_period,
        'displacement': batch.displacement.tolist(), 'force': batch.force.tolist(),
        'setpoint': batch.setpoint.tolist(), 'temperature': float(batch.temperature),
        'status_flags': int(batch.status_flags), 'frames_lost': int(batch.frames_lost)}


def setpoint_batch_record(t: float, batch: tuple, source: str, sample_period: float) -> tuple[str, str, dict]:
    """(topic, type, fields) of an excitation setpoint batch (first, displacement [m], stream id, end, block)
    published at `t` [s] (msg_defs/SetpointBatch).
    """
    first, x, stream_id, end, block = batch
    return f'{NS}/setpoints', 'msg_defs/msg/SetpointBatch', {
        'header': header(t), 'stream_id': int(stream_id), 'source': source, 'first_sequence': int(first),
        'sample_period': sample_period, 'displacement': x.tolist(), 'block_index': int(block),
        'end_of_stream': bool(end)}
