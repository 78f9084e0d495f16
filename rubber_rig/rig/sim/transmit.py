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
through its transmit queue on the (possibly timed and flooded) bus. The transmitter reports the controller's
shared state (state.ControllerState) and keeps its own: the samples not yet sent, the frame counters, the
periodic frames' schedule, frames held back by a fault injection.
"""
from typing import Callable

import can

from ..can.protocol import STATE_CODE, STATUS_SEQ_MOD, cycle_time
from ..can.timing import frame_time
from .constants import DEVICE_CODE, FIRMWARE
from .state import ControllerState


class FeedbackTransmitter:
    """The transmit side of the simulated controller on `bus`: the sample frames `frames` and the other frames of
    `proto`, reporting `shared`, through the FaultInjector `faults` at the time fault_time() [s]; options the
    SimOptions (host timeout, rated velocity, temperature noise, protocol version), temperature [degC] the
    specimen's, rng the noise of the temperature readings and of the feedback_jitter defect; flood_bus another
    node on the bus for bus_flood faults; defects: deliberate protocol defects (conformance testing).
    """

    def __init__(self, shared: ControllerState, bus, proto, frames, faults, fault_time: Callable[[], float],
                 options, fs: float, temperature: float, rng, defects: frozenset, flood_bus=None):
        self.shared, self.bus, self.proto, self.frames, self.faults = shared, bus, proto, frames, faults
        self.fault_time, self.opt, self.fs, self.temperature, self.rng = fault_time, options, fs, temperature, rng
        self.defects, self.flood_bus = defects, flood_bus
        self._fb = ([], [], [])           # measured x, f and applied u not yet sent
        self._fb_first = 0                # sequence of the first of them
        self._per = frames.feedback_slots if 'feedback_six_per_frame' in defects else frames.feedback_per_frame
        self._seq_mask = 0xFFFF if 'sequence_16bit' in defects else -1
        self._flood_owed, self._flood_at = 0.0, None     # bus_flood: frames owed between wake-ups
        self.held = []                    # (release_tick, message) for delayed frames
        self._jitter_until = 0            # feedback_jitter defect: release tick of the last held feedback frame
        self._jitter = 'feedback_jitter' in defects
        self._hb = self._st = self._tc = 0
        hb_period = 0.08 if 'heartbeat_80ms' in defects else cycle_time('ControllerHeartbeat')
        self.periods = {'ControllerHeartbeat': hb_period, **{name: cycle_time(name) for name in (
            'ControllerStatus', 'Temperature', 'ControllerIdentity')}}
        self._hb_every, self._st_every, self._tc_every, self._id_every = (   # in ticks
            max(1, round(period * fs)) for period in self.periods.values())
        self.idle_due = {}                # frame name -> clock time it is next due while idle (paced)
        self.id_next_tick = 0             # rig tick the next ControllerIdentity is due at while ticking

    def ticks_to_periodic(self) -> int:
        """Ticks from now to the next tick a periodic frame is due at (a block of ticks ends there)."""
        ticks = self.shared.ticks
        return min(self._st_every - ticks % self._st_every, self._hb_every - ticks % self._hb_every,
                   self._tc_every - ticks % self._tc_every, self.id_next_tick - ticks)

    def start_periods(self, now: float):
        """Power-up at `now` [s]: status and identity go out, the periodic frames' schedule starts."""
        self.housekeeping(force=True)
        self.send_identity()
        self.id_next_tick = self.shared.ticks + self._id_every
        self.idle_due = {name: now + period for name, period in self.periods.items()}

    def queue_feedback(self, first: int, xm: list, fm: list, u: list):
        """Samples first, first + 1, ... (measured displacement and force, applied command) for the feedback
        frames; every frame that is full goes out now.
        """
        fx, ff, fu = self._fb
        if not fx and self._per == 1 and not self.faults.faults and not self._jitter:
            self._each_straight_out(first, xm, fm, u)
            return
        if not fx:
            self._fb_first = first
        fx.extend(xm)
        ff.extend(fm)
        fu.extend(u)
        per = self._per      # defect feedback_six_per_frame: 6 samples (5 ms of latency) in each frame
        while len(self._fb[0]) >= per:
            self.send_feedback(per)

    def _each_straight_out(self, first: int, xm: list, fm: list, u: list):
        """queue_feedback() with one sample per frame and nothing injected (a simulated rig at 1 kHz): each sample
        its frame, straight onto the bus - the frames send_feedback(1) would send, without the lists between.
        """
        encode, mask, put = self.frames.encode_feedback, self._seq_mask, self.put
        for k in range(len(xm)):
            for m in encode((first + k) & mask, xm[k:k + 1], fm[k:k + 1], u[k:k + 1]):
                put(m)
        self._fb_first = first + len(xm)

    def send_feedback(self, count: int = None):
        """Send the first `count` samples not yet sent (default: all; a packed frame may carry fewer than it
        holds).
        """
        fx, ff, fu = self._fb
        k = len(fx) if count is None else count
        if k:
            first = self._fb_first & self._seq_mask
            if k == len(fx):     # all of them (at 1 kHz each sample is a frame of its own)
                frames, self._fb = self.frames.encode_feedback(first, fx, ff, fu), ([], [], [])
            else:
                frames = self.frames.encode_feedback(first, fx[:k], ff[:k], fu[:k])
                self._fb = (fx[k:], ff[k:], fu[k:])
            for m in frames:
                self._transmit('Feedback', m)
            self._fb_first += k

    def housekeeping(self, force=False):
        """Status, heartbeat and temperature at their DBC cycle times of rig time (or now if force)."""
        sh = self.shared
        ticks, code = sh.ticks, STATE_CODE[sh.state]
        if force or ticks % self._st_every == 0:
            self._send_status(code)
        if force or ticks % self._hb_every == 0:
            self._send_heartbeat(code)
        if force or ticks % self._tc_every == 0:
            self._send_temperature()
        if ticks >= self.id_next_tick:
            self.send_identity()
            self.id_next_tick = ticks + self._id_every

    def idle_housekeeping(self, now: float):
        """Paced, not ticking: each periodic frame at its own period of clock time (CTRL-HB-1, CTRL-ST-1)."""
        due, code = self.idle_due, STATE_CODE[self.shared.state]
        for name, period in self.periods.items():
            at = due.get(name, now)
            if now + 1e-4 < at:
                continue
            due[name] = max(at + period, now)
            if name == 'ControllerIdentity':
                self.send_identity()
                self.id_next_tick = self.shared.ticks + self._id_every
            elif name == 'Temperature':
                self._send_temperature()
            elif name == 'ControllerStatus':
                self._send_status(code)
            else:
                self._send_heartbeat(code)

    def _send_status(self, code: int):
        sh = self.shared
        self._st = (self._st + 1) % 16
        level = len(sh.buffer)             # setpoints queued beyond the last tick (CTRL-ST-4)
        if 'buffer_in_frames' in self.defects:
            level //= self.frames.setpoints_per_frame
        self._send('ControllerStatus', {'ST_State': code, 'ST_Counter': self._st, 'ST_Faults': sh.fault_bits,
                                        'ST_LastSequence': (sh.next_seq - 1) % STATUS_SEQ_MOD,
                                        'ST_BufferLevel': min(level, 65535)})

    def _send_heartbeat(self, code: int):
        if 'no_heartbeat' in self.defects:     # a controller whose firmware never sends its heartbeat
            return
        self._hb = (self._hb + 1) % 256
        self._send('ControllerHeartbeat', {'HB_Counter': self._hb, 'HB_State': code})

    def _send_temperature(self):
        self._tc = (self._tc + 1) % 256
        temp = self.temperature + self.opt.temperature_noise * float(self.rng.standard_normal())
        self._send('Temperature', {'TEMP_Specimen': temp, 'TEMP_Counter': self._tc})

    def send_identity(self):
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
        if not self.faults.faults and not self._jitter:     # nothing injected: straight onto the bus
            self.put(msg)
            return
        ticks = self.shared.ticks
        for delay, m in self.faults.transmit(name, msg, self.fault_time()):
            if name == 'Feedback' and self._jitter:
                # 0-8 ms late, never overtaking the frame before it
                late = int(self.rng.integers(0, int(0.008 * self.fs) + 1))
                self._jitter_until = max(self._jitter_until, ticks + late)
                delay = self._jitter_until - ticks
            if delay:
                self.held.append((ticks + delay, m))
            else:
                self.put(m)

    def flood(self, now: float):
        """bus_flood faults: the other node sends its frames for the time since the last call (its own transmit
        queue full is its problem: those frames are simply not sent).
        """
        active = [f for f in self.faults.faults if f.type == 'bus_flood' and f.active(self.fault_time())]
        last, self._flood_at = self._flood_at, now
        if not active or last is None:
            self._flood_owed = 0.0
            return
        duration = frame_time(8, self.flood_bus.medium.bitrate)
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

    def put(self, msg):
        """Hand a frame to the bus; a full transmit queue (an overloaded bus) loses it, as a controller's
        mailboxes would: counted, and the host sees the gap.
        """
        try:
            self.bus.send(msg)
        except can.CanOperationError:
            self.shared.counters['tx_dropped'] += 1

    def release_held(self):
        """Delayed frames whose release tick has come go out."""
        if self.held:
            ticks = self.shared.ticks
            due = [m for r, m in self.held if r <= ticks]
            if due:
                self.held = [(r, m) for r, m in self.held if r > ticks]
                for m in due:
                    self.put(m)

    def release_all_held(self):
        """The controller stops ticking: delayed frames still go out, now."""
        for _, m in self.held:
            self.put(m)
        self.held = []
