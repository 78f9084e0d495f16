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


"""A timestamped record of the frames on the rig bus, decoded with the DBC: what the conformance checks read.

The same Trace is filled live by the conformance run (`Trace.add` for every frame sent and received) and from a
raw CAN log (`read_log`: Vector BLF/ASC or candump -L, as python-can reads them), so the offline and the online
checks are one piece of code. Who sent a frame is what the DBC says of it (HOST or CONTROLLER), not the log's
Tx/Rx flag, so a log recorded on either end, or by a bus monitor, reads the same.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import can

from ..can.canlog import CanLogError, log_format
from ..can.canlog_text import frames_until_damage
from ..can.frames import PROFILES, SampleFrames
from ..can.protocol import MalformedFrame, Protocol


@dataclass
class Frame:
    """One frame: t [s] (the receiver's timestamp), `host` True when the DBC names HOST as its sender (None for
    an unknown identifier), `name` (DBC message name or None), decoded `signals` (non-sample frames), `samples`
    (feedback: (raw sequence, x, f, u); setpoints: (raw sequence, values)) and `malformed` (wrong length or CRC).
    """

    t: float
    msg: can.Message
    name: str | None = None
    host: bool | None = None
    signals: dict | None = None
    samples: tuple | None = None
    malformed: bool = False
    foreign: bool = False     # extended identifier, remote or error frame: not part of the protocol


@dataclass
class Trace:
    """Frames in the order they were seen, with the sample rate [Hz] they are judged at."""

    sample_rate: float
    frames: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    # (start, end) [s] windows in which the host recording the trace was late (conformance.host_timing; live
    # runs only): a timing violation inside one cannot be blamed on the controller
    host_late: list = field(default_factory=list)
    source: str = 'live'

    def __post_init__(self):
        self.proto = Protocol()
        self._by_id = {}
        self.modulus = {}   # sample frame name -> 2**bits of its sequence field
        for profile in PROFILES:
            sf = SampleFrames(profile, self.proto.db, self.sample_rate)
            for name, codec in sf.codecs.items():
                self._by_id.setdefault(codec.frame_id, sf)
                self.modulus[name] = 1 << self.proto.by_name[name].signals[0].length
        self._host_ids = {m.frame_id for m in self.proto.db.messages if 'HOST' in m.senders}

    def add(self, msg: can.Message, t: float = None) -> Frame:
        """Decode and append one frame seen at t [s] (default: its timestamp, else the wall clock)."""
        if t is None:
            t = msg.timestamp if msg.timestamp else time.time()
        fr = Frame(float(t), msg)
        self.frames.append(fr)
        if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame:
            fr.foreign = True
            return fr
        m = self.proto.by_id.get(msg.arbitration_id)
        if m is None:
            return fr
        fr.name, fr.host = m.name, msg.arbitration_id in self._host_ids
        sf = self._by_id.get(msg.arbitration_id)
        try:
            if sf is not None and m.name in sf.setpoint_names:
                fr.samples = sf.decode_setpoints(msg)
            elif sf is not None:
                fr.samples = sf.decode_feedback(msg)   # None for the first half of a classic pair
            else:
                fr.signals = self.proto.decode(msg)[1]
        except MalformedFrame:
            fr.malformed = True
        return fr

    # ---- views
    def valid(self, name: str, since: float = -math.inf, until: float = math.inf) -> list:
        """The well-formed frames called `name` seen in [since, until)."""
        return [f for f in self.frames if f.name == name and not f.malformed and since <= f.t < until]

    @property
    def start(self) -> float:
        return self.frames[0].t if self.frames else math.nan

    @property
    def end(self) -> float:
        return self.frames[-1].t if self.frames else math.nan


def read_log(path, sample_rate: float) -> Trace:
    """A Trace from the raw CAN log `path` (.blf, .asc, .log). A log that is damaged part way is read up to the
    damage, with a warning in Trace.warnings. CanLogError for a file that is no readable log.
    """
    p = Path(str(path)).expanduser()
    log_format(p)
    if not p.is_file():
        raise CanLogError(f'{p}: no such CAN log')
    trace = Trace(float(sample_rate), source=str(p))
    try:
        reader = can.LogReader(str(p))
    except Exception as exc:   # noqa: BLE001 - python-can raises anything from struct.error to its own errors
        raise CanLogError(f'{p}: not a readable CAN log: {exc or type(exc).__name__}') from None
    damaged = []
    try:
        for msg in frames_until_damage(reader, damaged):
            trace.add(msg, float(msg.timestamp))
        if damaged:
            trace.warnings.append(f'{p}: unreadable after frame {len(trace.frames)}: {damaged[0]}')
    finally:
        try:
            reader.stop()
        except Exception:   # noqa: BLE001
            pass
    if not trace.frames:
        raise CanLogError(f'{p}: holds no CAN frame')
    return trace
