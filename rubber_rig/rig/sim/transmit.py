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

"""What the simulated controller sends: feedback samples, status, heartbeat, temperature and identity frames,
through its transmit queue on the (possibly timed and flooded) bus.
"""

import can

from ..can.protocol import (
    STATE_CODE,
    STATUS_SEQ_MOD,
)
from ..can.timing import frame_time
from .constants import DEVICE_CODE, FIRMWARE


class ControllerTransmit:
    """The transmit side of SimController (its state lives there)."""

    def _queue_feedback(self, first: int, xm: list, fm: list, u: list):
        """Samples first, first + 1, ... (measured displacement and force, applied command) for the feedback
        frames; every frame that is full goes out now.
        """
        fx, ff, fu = self._fb
        if not fx:
            self._fb_first = first
        fx.extend(xm)
        ff.extend(fm)
        fu.extend(u)
        per = self.frames.feedback_per_frame
        if 'feedback_six_per_frame' in self.defects:   # gathers 6 samples (5 ms of latency) into each frame
            per = self.frames.feedback_slots
        while len(self._fb[0]) >= per:
            self._send_feedback(per)

    def _send_feedback(self, count: int = None):
        """Send the first `count` samples not yet sent (default: all; a packed frame may carry fewer than it
        holds).
        """
        fx, ff, fu = self._fb
        k = len(fx) if count is None else count
        if k:
            first = self._fb_first & 0xFFFF if 'sequence_16bit' in self.defects else self._fb_first
            for m in self.frames.encode_feedback(first, fx[:k], ff[:k], fu[:k]):
                self._transmit('Feedback', m)
            self._fb = (fx[k:], ff[k:], fu[k:])
            self._fb_first += k

    def _housekeeping(self, force=False):
        """Status, heartbeat and temperature at their DBC cycle times of rig time (or now if force)."""
        code = STATE_CODE[self.state]
        if force or self.ticks % self._st_every == 0:
            self._send_status(code)
        if force or self.ticks % self._hb_every == 0:
            self._send_heartbeat(code)
        if force or self.ticks % self._tc_every == 0:
            self._send_temperature()
        if self.ticks >= self._id_next_tick:
            self._send_identity()
            self._id_next_tick = self.ticks + self._id_every

    def _send_status(self, code: int):
        self._st = (self._st + 1) % 16
        self._send('ControllerStatus', {'ST_State': code, 'ST_Counter': self._st, 'ST_Faults': self.fault_bits,
                                        'ST_LastSequence': (self.next_seq - 1) % STATUS_SEQ_MOD,
                                        'ST_BufferLevel': min(self._buffer_level(), 65535)})

    def _buffer_level(self) -> int:
        """Setpoints queued beyond the last tick (CTRL-ST-4)."""
        if 'buffer_in_frames' in self.defects:
            return len(self.buffer) // self.frames.setpoints_per_frame
        return len(self.buffer)

    def _send_heartbeat(self, code: int):
        if 'no_heartbeat' in self.defects:     # a controller whose firmware never sends its heartbeat
            return
        self._hb = (self._hb + 1) % 256
        self._send('ControllerHeartbeat', {'HB_Counter': self._hb, 'HB_State': code})

    def _send_temperature(self):
        self._tc = (self._tc + 1) % 256
        temp = self.temperature + self.opt.temperature_noise * float(self.temp_rng.standard_normal())
        self._send('Temperature', {'TEMP_Specimen': temp, 'TEMP_Counter': self._tc})

    def _idle_housekeeping(self, now: float):
        """Paced, not ticking: each periodic frame at its own period of wall-clock time (CTRL-HB-1, CTRL-ST-1)."""
        due = self._idle_due
        for name, period in self._periods.items():
            at = due.get(name, now)
            if now + 1e-4 < at:
                continue
            due[name] = max(at + period, now)
            if name == 'ControllerIdentity':
                self._send_identity()
                self._id_next_tick = self.ticks + self._id_every
            elif name == 'Temperature':
                self._send_temperature()
            elif name == 'ControllerStatus':
                self._send_status(STATE_CODE[self.state])
            else:
                self._send_heartbeat(STATE_CODE[self.state])

    def _send_identity(self):
        """ControllerIdentity (CTRL-ID-1): protocol version, device, firmware, host timeout, rated velocity."""
        rated = min(self.opt.actuator_velocity_max, 6.5535)
        if 'rated_velocity_byte_swapped' in self.defects:    # the 16-bit field sent in the wrong byte order
            raw = round(rated / 1e-4)
            rated = (((raw & 0xFF) << 8) | (raw >> 8)) * 1e-4
        self._send('ControllerIdentity', {'CI_Protocol': self.opt.protocol_version, 'CI_Device': DEVICE_CODE,
                                          'CI_Firmware': FIRMWARE, 'CI_HostTimeout': min(self.opt.host_timeout, 2.55),
                                          'CI_VelocityMax': rated})

    def _send(self, name, signals):
        self._transmit(name, self.proto.encode(name, signals))

    def _transmit(self, name, msg):
        """Put msg on the bus through the fault injector (name: the frame's role, e.g. 'Feedback')."""
        for delay, m in self.faults.transmit(name, msg, self.fault_time()):
            if name == 'Feedback' and 'feedback_jitter' in self.defects:
                # 0-8 ms late, never overtaking the frame before it
                late = int(self.temp_rng.integers(0, int(0.008 * self.fs) + 1))
                self._jitter_until = max(self._jitter_until, self.ticks + late)
                delay = self._jitter_until - self.ticks
            if delay:
                self._held.append((self.ticks + delay, m))
            else:
                self._put(m)

    def _flood(self, now: float):
        """bus_flood faults: the other node sends its frames for the time since the last call (its own transmit
        queue full is its problem: those frames are simply not sent).
        """
        active = [f for f in self.faults.faults if f.type == 'bus_flood' and f.active(self.fault_time())]
        last, self._flood_at = self._flood_at, now
        if not active or last is None:
            self._flood_owed = 0.0
            return
        medium = self.flood_bus.medium
        duration = frame_time(8, medium.bitrate)
        for f in active:
            self._flood_owed += f.load * (now - last) / duration
            msg = can.Message(arbitration_id=f.frame_id, data=bytes(8), is_extended_id=False)
            while self._flood_owed >= 1.0:
                self._flood_owed -= 1.0
                try:
                    self.flood_bus.send(msg)
                except can.CanOperationError:
                    self._flood_owed = 0.0
                    break

    def _put(self, msg):
        """Hand a frame to the bus; a full transmit queue (an overloaded bus) loses it, as a controller's
        mailboxes would: counted, and the host sees the gap.
        """
        try:
            self.bus.send(msg)
        except can.CanOperationError:
            self.counters['tx_dropped'] += 1

    def _release_held(self):
        if self._held:
            due = [m for r, m in self._held if r <= self.ticks]
            if due:
                self._held = [(r, m) for r, m in self._held if r > self.ticks]
                for m in due:
                    self._put(m)
