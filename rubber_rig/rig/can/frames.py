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


"""The frame profiles that carry samples over the rig bus (all defined in rubber_rig.dbc).

========  ===========================================  ============================================  ==========
profile   setpoints (host -> controller)               feedback (controller -> host)                 sequence
========  ===========================================  ============================================  ==========
packed    SetpointPacked, CAN FD 64 B: up to 19        FeedbackPacked, CAN FD 64 B: up to 6          32 bit
          samples per frame                            samples per frame (as many as 1 ms holds)
single    Setpoint, 8 B: one sample per frame          Feedback, CAN FD 12 B: one sample per frame   16 bit
classic   Setpoint, 8 B                                FeedbackApplied (6 B) + FeedbackMeasured      16 bit
                                                       (8 B) per sample: classic CAN only
========  ===========================================  ============================================  ==========

Both ends (driver and simulated controller) and the CAN log reader use these classes, so a profile is defined
once. Sequence numbers are the sample index modulo 2**bits; protocol.unwrap restores the full index.
"""
from __future__ import annotations

import can

from .codec import ByteCodec
from .protocol import MalformedFrame

PROFILES = ('packed', 'single', 'classic')
SETPOINT_FRAMES = {'packed': ('SetpointPacked',), 'single': ('Setpoint',), 'classic': ('Setpoint',)}
FEEDBACK_FRAMES = {'packed': ('FeedbackPacked',), 'single': ('Feedback',),
                   'classic': ('FeedbackApplied', 'FeedbackMeasured')}
# the longest a packed feedback frame waits for samples [s]: packing never adds more latency than this
FEEDBACK_PACK_TIME = 1e-3


def default_profile(fd: bool) -> str:
    """The profile a bus runs unless configured otherwise: packed on CAN FD, classic on classic CAN."""
    return 'packed' if fd else 'classic'


class SampleFrames:
    """Encode and decode the per-sample frames of `profile` (one of PROFILES) with the DBC of `db`.

    setpoints_per_frame / feedback_per_frame: samples one frame carries (feedback_per_frame at sample rate fs
    is what the controller packs: as many samples as FEEDBACK_PACK_TIME holds, at most the frame's slots).
    """

    def __init__(self, profile: str, db, fs: float = 1000.0):
        if profile not in PROFILES:
            raise ValueError(f'unknown frame profile {profile!r} (one of {", ".join(PROFILES)})')
        self.profile = profile
        self.setpoint_names, self.feedback_names = SETPOINT_FRAMES[profile], FEEDBACK_FRAMES[profile]
        self.codecs = {name: ByteCodec(db.get_message_by_name(name))
                       for name in self.setpoint_names + self.feedback_names}
        self.by_id = {c.frame_id: c for c in self.codecs.values()}
        sp = self.codecs[self.setpoint_names[0]]
        fb = self.codecs[self.feedback_names[0]]
        # the first signal of every sample frame is its sequence number
        self.setpoint_modulus = 1 << db.get_message_by_name(sp.name).signals[0].length
        self.feedback_modulus = 1 << db.get_message_by_name(fb.name).signals[0].length
        if profile == 'packed':
            self.setpoints_per_frame = len(sp.names) - 2
            self.feedback_slots = (len(fb.names) - 2) // 3
        else:
            self.setpoints_per_frame = self.feedback_slots = 1
        self.feedback_per_frame = self.feedback_pack(fs)
        self._sp, self._fb = sp, fb
        # classic: frames waiting for their pair, by the low 8 bits of the sequence (a lost partner leaves an
        # entry that the frame of the same slot 256 samples later replaces)
        self._applied, self._measured = {}, {}

    def feedback_pack(self, fs: float) -> int:
        """Samples per feedback frame at sample rate fs [Hz]: as many as FEEDBACK_PACK_TIME holds (at least 1, at
        most the frame's slots).
        """
        return max(1, min(self.feedback_slots, int(fs * FEEDBACK_PACK_TIME + 1e-9)))

    def pack_ranges(self) -> list:
        """[(rate_lo, rate_hi, samples per feedback frame)]: the sample-rate ranges [Hz] of constant packing."""
        edges = [k / FEEDBACK_PACK_TIME for k in range(2, self.feedback_slots + 1)]
        lows, highs = [0.0] + edges, edges + [float('inf')]
        return [(lo, hi, self.feedback_pack(lo)) for lo, hi in zip(lows, highs, strict=True)]

    def _message(self, codec: ByteCodec, values) -> can.Message:
        return can.Message(arbitration_id=codec.frame_id, data=codec.encode(values), is_extended_id=False,
                           is_fd=codec.is_fd, bitrate_switch=codec.is_fd, check=False)

    # ---- host -> controller
    def encode_setpoints(self, first: int, values) -> list:
        """Frames for setpoints `values` [m] of samples first, first + 1, ... (a list of floats)."""
        codec, per, mod = self._sp, self.setpoints_per_frame, self.setpoint_modulus
        if per == 1:
            return [self._message(codec, ((first + i) % mod, v)) for i, v in enumerate(values)]
        out = []
        for i in range(0, len(values), per):
            chunk = values[i:i + per]
            out.append(self._message(codec, [(first + i) % mod, len(chunk)] + chunk))   # unused slots: 0
        return out

    def decode_setpoints(self, msg) -> tuple:
        """(sequence mod setpoint_modulus, [setpoints]) of a setpoint frame; MalformedFrame if it is broken."""
        codec = self.by_id[msg.arbitration_id]
        frame = codec.unpack(msg.data)
        if frame is None:
            raise MalformedFrame(codec.check(msg.data))
        if self.setpoints_per_frame == 1:
            v = codec.fields(frame)
            return v[0], v[1:2]
        seq, n = codec.fields(frame, 2)      # sequence and count: only the slots in use are decoded
        if not 1 <= n <= self.setpoints_per_frame:
            raise MalformedFrame(f'{codec.name}: count {n} outside 1..{self.setpoints_per_frame}')
        return seq, codec.fields(frame, 2 + n, start=2)

    # ---- controller -> host
    def encode_feedback(self, first: int, x, f, u) -> list:
        """Frames for measured samples first.. (displacement x [m], force f [N], applied command u [m]: lists of
        at most feedback_per_frame floats).
        """
        mod = self.feedback_modulus
        if self.profile == 'packed':
            if len(x) == 1:     # at 1 kHz every frame carries one sample
                return [self._message(self._fb, (first % mod, 1, x[0], f[0], u[0]))]
            values = [first % mod, len(x)]
            for sample in zip(x, f, u, strict=True):   # unused slots: 0
                values += sample
            return [self._message(self._fb, values)]
        out = []
        for i in range(len(x)):
            seq = first + i
            if self.profile == 'single':
                out.append(self._message(self._fb, (seq % mod, x[i], f[i], u[i])))
            else:
                out.append(self._message(self._fb, (seq % mod, u[i])))
                out.append(self._message(self.codecs['FeedbackMeasured'], (seq % 256, x[i], f[i])))
        return out

    def decode_feedback(self, msg):
        """(sequence mod feedback_modulus, x, f, u lists) of the samples a feedback frame completes, or None
        (classic: the first frame of a tick's pair waits for the other; a sample whose partner frame was lost is
        never completed, so it counts as lost). MalformedFrame if it is broken.
        """
        codec = self.by_id[msg.arbitration_id]
        frame = codec.unpack(msg.data)
        if frame is None:
            raise MalformedFrame(codec.check(msg.data))
        if self.profile == 'packed':
            v = codec.fields(frame, 5)           # sequence, count and the first sample's slot
            if v[1] == 1:                        # at 1 kHz every frame carries one sample
                return v[0], v[2:3], v[3:4], v[4:5]
            seq, n = v[:2]                       # only the slots in use are decoded
            if not 1 <= n <= self.feedback_slots:
                raise MalformedFrame(f'{codec.name}: count {n} outside 1..{self.feedback_slots}')
            v = codec.fields(frame, 2 + 3 * n, start=2)
            return seq, v[0::3], v[1::3], v[2::3]
        v = codec.fields(frame)
        if self.profile == 'single':
            return v[0], [v[1]], [v[2]], [v[3]]
        # classic: the two frames of a tick pair up by sequence, in either order (a controller with several
        # frames queued sends them by identifier priority: all FeedbackApplied before their FeedbackMeasured)
        if codec.name == 'FeedbackApplied':
            seq, u = v
            measured = self._measured.pop(seq % 256, None)
            if measured is not None:
                return seq, [measured[0]], [measured[1]], [u]
            self._applied[seq % 256] = (seq, u)
            return None
        seq8, x, f = v
        applied = self._applied.pop(seq8, None)
        if applied is None:
            self._measured[seq8] = (x, f)
            return None
        return applied[0], [x], [f], [applied[1]]
