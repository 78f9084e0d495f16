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
"""How long CAN frames occupy the bus, and how much of it the rig protocol needs at a sample rate.

A frame's duration is its bit count divided by the bitrate of each phase. Bit stuffing (a complementary bit
after five equal ones) depends on the payload; the worst case, used here unless worst_case=False, is one
stuff bit per four bits of the stuffed fields after the first (ISO 11898-1):

* classic CAN, 11-bit identifier: SOF, identifier, RTR, IDE, r0, DLC, data and CRC are stuffed
  (34 + 8 n bits), followed by 13 fixed bits (CRC delimiter, ACK slot and delimiter, 7 EOF, 3 intermission):
  8 data bytes take 111 bits unstuffed and 135 bits worst case, 0.111-0.135 ms at 1 Mbit/s;
* CAN FD, 11-bit identifier, with bit-rate switch: the arbitration phase (SOF, identifier, RRS, IDE, FDF, res,
  BRS: 17 bits, plus stuffing) and the tail (CRC delimiter, ACK, EOF, intermission: 13 bits) run at the
  nominal bitrate; ESI, DLC, data, the stuff count (4 bits and its fixed stuff bit) and the CRC (17 bits up
  to 16 data bytes, 21 above, with one fixed stuff bit per 4 bits) at the data bitrate. Payloads are padded to
  the next valid FD length (12, 16, 20, 24, 32, 48, 64 bytes). A 12-byte frame at 1/5 Mbit/s takes
  0.056 ms without stuffing, 0.065 ms worst case.

:func:`protocol_load` adds the frames the rig protocol sends per second at a sample rate: the setpoint and
feedback frames of the frame profile (rubber_rig.rig.can.frames: packed, single or classic), and the periodic
frames at their DBC GenMsgCycleTime. Bus load is the fraction of
each second the bus is busy; rig buses are laid out for 50-70 % so that high-priority frames still get through.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .frames import FEEDBACK_FRAMES, SETPOINT_FRAMES, SampleFrames, default_profile
from .protocol import DBC_PATH, Protocol

FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
# frames sent only on events (not counted in the load)
EVENT_FRAMES = ('HostCommand', 'HostLimits', 'HostStreamStart')
SAMPLE_FRAMES = {name for names in (*SETPOINT_FRAMES.values(), *FEEDBACK_FRAMES.values()) for name in names}


def fd_length(n: int) -> int:
    """The CAN FD payload length [bytes] that carries n bytes (the next valid DLC length)."""
    for length in FD_LENGTHS:
        if n <= length:
            return length
    raise ValueError(f'a CAN FD frame carries at most 64 bytes, not {n}')


def _stuff(bits: int, worst_case: bool) -> int:
    return (bits - 1) // 4 if worst_case else 0


def frame_bits(data_bytes: int, fd: bool = False, bitrate_switch: bool = True, worst_case: bool = True,
               extended: bool = False) -> tuple[int, int]:
    """(bits at the nominal bitrate, bits at the data bitrate) of one data frame with an 11-bit identifier
    (29-bit with extended: 20 more arbitration bits in a classic frame, SRR, IDE and 18 identifier bits;
    19 in an FD frame, which has no r1).

    Classic frames (fd False) carry at most 8 bytes and run entirely at the nominal bitrate (second item 0);
    FD frames without bitrate_switch too.
    """
    if not fd:
        if not 0 <= data_bytes <= 8:
            raise ValueError(f'a classic CAN frame carries 0-8 bytes, not {data_bytes}')
        stuffed = 34 + (20 if extended else 0) + 8 * data_bytes
        return stuffed + _stuff(stuffed, worst_case) + 13, 0
    n = fd_length(data_bytes)
    head = 17 + (19 if extended else 0)
    arbitration = head + _stuff(head, worst_case)
    data_field = 1 + 4 + 8 * n                                   # ESI, DLC, data
    crc = 17 if n <= 16 else 21
    data_phase = data_field + _stuff(data_field, worst_case) + 5 + crc + math.ceil(crc / 4)
    tail = 13
    if bitrate_switch:
        return arbitration + tail, data_phase
    return arbitration + data_phase + tail, 0


def frame_time(data_bytes: int, bitrate: float, data_bitrate: float = None, fd: bool = False,
               bitrate_switch: bool = True, worst_case: bool = True) -> float:
    """Duration [s] of one data frame on the bus (see :func:`frame_bits`); ``data_bitrate`` defaults to
    bitrate.
    """
    nominal, data = frame_bits(data_bytes, fd, bitrate_switch, worst_case)
    return nominal / bitrate + data / (data_bitrate or bitrate)


@dataclass(frozen=True)
class BusLoad:
    """The protocol's use of a bus: load [-] (busy fraction of each second), per_sample [s] of bus time
    the per-sample frames take, periodic [s/s] the periodic frames take, frames {name: (frames/s,
    duration [s])}; max_rate [Hz] the sample rate at which the bus would be full and rate_at (a
    function) the sample rate at a given load. segments: ((rate_lo, rate_hi, per_sample), ...), the bus time
    per sample over the sample-rate ranges of constant packing (packed feedback frames fill up with the rate).
    """

    sample_rate: float
    load: float
    per_sample: float
    periodic: float
    frames: dict
    segments: tuple = ()

    @property
    def max_rate(self) -> float:
        return self.rate_at(1.0)

    def rate_at(self, load: float) -> float:
        """The highest sample rate [Hz] whose load stays at or below load (e.g. 0.5 for 50 %)."""
        best = 0.0
        for lo, hi, per_sample in self.segments or ((0.0, math.inf, self.per_sample),):
            rate = (load - self.periodic) / per_sample
            if rate >= lo:
                best = max(best, min(rate, hi))
        return best


def protocol_load(sample_rate: float, bitrate: float, data_bitrate: float = None, fd: bool = True,
                  protocol: Protocol = None, worst_case: bool = True, profile: str = None) -> BusLoad:
    """Bus load of the rig protocol (the project's DBC) with the frames of `profile` (rubber_rig.rig.can.frames;
    default: packed on CAN FD, classic otherwise) at sample_rate [Hz] on a bus of bitrate (and, with fd,
    data_bitrate) [bit/s]. A frame that carries k samples costs its duration / k per sample (a partly filled
    frame at the end of a stream is not counted). ValueError when the bus cannot carry a frame of the profile
    (an FD frame on a classic bus).
    """
    proto = protocol or Protocol()
    profile = profile or default_profile(fd)
    sample = SampleFrames(profile, proto.db, sample_rate)
    frames, per_sample, periodic, setpoint_time, feedback_time = {}, 0.0, 0.0, 0.0, 0.0
    for m in proto.db.messages:
        if m.name in EVENT_FRAMES or (m.name in SAMPLE_FRAMES and m.name not in sample.codecs):
            continue
        if m.is_fd and not fd:
            raise ValueError(f'{DBC_PATH.name}: {m.name} is a CAN FD frame ({m.length} bytes); a classic CAN bus '
                             f'cannot carry the {profile} profile')
        t = frame_time(m.length, bitrate, data_bitrate, fd=m.is_fd, bitrate_switch=m.is_fd, worst_case=worst_case)
        if m.name in sample.codecs:
            per = sample.setpoints_per_frame if m.name in sample.setpoint_names else sample.feedback_per_frame
            frames[m.name] = (float(sample_rate) / per, t)
            per_sample += t / per
            if m.name in sample.setpoint_names:
                setpoint_time += t / per
            else:
                feedback_time += t
        elif m.cycle_time:
            rate = 1000.0 / m.cycle_time
            frames[m.name] = (rate, t)
            periodic += rate * t
    segments = tuple((lo, hi, setpoint_time + feedback_time / k) for lo, hi, k in sample.pack_ranges())
    return BusLoad(float(sample_rate), per_sample * sample_rate + periodic, per_sample, periodic, frames, segments)
