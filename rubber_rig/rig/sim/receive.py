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

"""What the simulated controller does with each frame it receives: commands, host limits and heartbeats, and
setpoints (accepted in order, or refused and counted as a real controller would).
"""
import math

from ...safety import DECEL_MAX
from ..can.protocol import (
    CMD_ABORT,
    CMD_DISABLE,
    CMD_HOLD,
    CMD_IDENTIFY,
    CMD_RESET,
    FAULT_DISPLACEMENT_LIMIT,
    FAULT_VELOCITY_LIMIT,
    MalformedFrame,
    meet,
    unwrap,
)
from .constants import LSB


class ControllerReceive:
    """The receive side of SimController (its state lives there)."""

    def _handle(self, msg):
        if msg.arbitration_id in self._setpoint_ids and not msg.is_extended_id:
            self._on_setpoints(msg)
            return
        try:
            decoded = self.proto.decode(msg)
        except MalformedFrame:   # CTRL-FRAME-2: counted, never applied
            self.counters['frames_bad'] += 1
            decoded = self._unchecked_host_limits(msg)
            if decoded is None:
                return
        if decoded is None:      # CTRL-FRAME-3: unknown, extended, remote frames change nothing
            return
        name, sig = decoded
        if name == 'HostStreamStart':
            self.accept_from = int(sig['HS_FirstSequence'])
        elif name == 'HostHeartbeat':
            self.last_host_hb = self.ticks
        elif name == 'HostLimits' and 'ignore_host_limits' not in self.defects:   # CTRL-LIM-1
            lo, hi = float(sig['HL_DisplacementMin']), float(sig['HL_DisplacementMax'])
            if lo < hi:
                # defect ignore_lower_limit: only the upper bound is kept (the downward direction never checked)
                self.lower = -math.inf if 'ignore_lower_limit' in self.defects else lo
                self.upper = hi
                self.decel_max = float(sig['HL_Deceleration']) or DECEL_MAX
                self._refuse_queued()
            else:                # min >= max: discarded whole, the limits stay as they were
                self.counters['frames_bad'] += 1
        elif name == 'HostCommand':
            code = int(sig['CMD_Code'])
            if code == CMD_DISABLE and 'ignore_disable' in self.defects:
                pass
            elif code in (CMD_ABORT, CMD_DISABLE):
                self.abort(float(sig['CMD_Argument']), 0, float(sig['CMD_RampVelocity']) or None)
            elif code == CMD_HOLD:
                self.abort(None, 0, float(sig['CMD_RampVelocity']) or None)
            elif code == CMD_IDENTIFY:
                if 'identify_answered_once' not in self.defects or not self._identified:
                    self._send_identity()   # CTRL-ID-1
                self._identified = True
            elif code == CMD_RESET and (self.state in ('fault', 'idle') or (   # CTRL-FAULT-2; CTRL-RESET-1
                    'reset_while_ramping' in self.defects and self.state == 'ramping_down')):
                self.fault_bits = 0
                self.state = 'idle'
                self._housekeeping(force=True)

    def _receive_all(self):
        """Handle every frame waiting on the bus."""
        msg = self.bus.recv(0)
        while msg is not None:
            self._handle(msg)
            msg = self.bus.recv(0)

    def _clear_fault_by_itself(self, now: float):
        """Defect fault_clears_after_500ms: a fault that goes back to idle 0.5 s after it began, without RESET."""
        if self.state != 'fault':
            self._fault_since = None
        elif self._fault_since is None:
            self._fault_since = now
        elif now - self._fault_since > 0.5:
            self.fault_bits, self.state, self._fault_since = 0, 'idle', None
            self._housekeeping(force=True)

    def _unchecked_host_limits(self, msg):
        """Defect host_limits_crc_unchecked: a HostLimits frame of the right length is decoded whatever its CRC;
        None for any other malformed frame (discarded, CTRL-FRAME-2).
        """
        m = self.proto.by_name['HostLimits']
        if 'host_limits_crc_unchecked' not in self.defects or msg.arbitration_id != m.frame_id \
                or len(msg.data) != m.length:
            return None
        return 'HostLimits', m.decode(bytes(msg.data), decode_choices=False, scaling=True)

    def _on_setpoints(self, msg):
        try:
            seq, values = self.frames.decode_setpoints(msg)
        except MalformedFrame:
            self.counters['frames_bad'] += 1
            return
        if self.state in ('ramping_down', 'fault'):
            return
        if self.state == 'idle':   # CTRL-STREAM-1, CTRL-STREAM-2: only from HS_FirstSequence on
            seq = unwrap(seq, self.accept_from if math.isfinite(self.accept_from) else self.next_seq,
                         self.frames.setpoint_modulus)
            if seq < self.accept_from:   # left over from an aborted stream, or no stream announced
                self.counters['setpoints_stale'] += 1
                return
        else:
            seq = unwrap(seq, self.next_seq, self.frames.setpoint_modulus)
        if self.state == 'idle':
            self.buffer.clear()
            self.next_seq = seq
            self.state = 'running'
            self.last_host_hb = self.ticks
            self._housekeeping(force=True)
        late, _ = meet(self.next_seq, seq, len(values))   # a gap ahead is bridged by holding (CTRL-STREAM-3)
        self.counters['setpoints_late'] += late
        if self._refuse_setpoints(seq, late, values):
            return
        if len(self.buffer) < self.frames.setpoint_modulus // 2:
            buffer = self.buffer
            for i in range(late, len(values)):
                buffer[seq + i] = values[i]

    def _refuse_queued(self):
        """CTRL-LIM-2: HostLimits that tighten while setpoints are queued bind those too: one outside the new limits
        is refused as if it had just arrived (flush, ramp to rest, displacement_limit).
        """
        tol = LSB + 1e-12
        if self.state in ('running', 'holding') and any(
                not self.lower - tol <= v <= self.upper + tol for v in self.buffer.values()):
            self.abort(0.0, FAULT_DISPLACEMENT_LIMIT)

    def _refuse_setpoints(self, seq: int, late: int, values) -> bool:
        """CTRL-LIM-2 / CTRL-LIM-3: a setpoint outside the host's limits, or one that steps faster than the rated
        velocity from the setpoint before it, is never applied: the controller faults and ramps to rest. True if
        the batch was refused.
        """
        tol = LSB + 1e-12
        step_max = (self.opt.actuator_velocity_max * 1.02) / self.fs + 2 * LSB
        prev = self.buffer.get(seq + late - 1)
        if prev is None and seq + late == self.next_seq:
            prev = self.u
        for i in range(late, len(values)):
            value = values[i]
            if not self.lower - tol <= value <= self.upper + tol:
                self.abort(0.0, FAULT_DISPLACEMENT_LIMIT)
                return True
            step = value - prev if prev is not None else 0.0
            if 'velocity_check_upward_only' not in self.defects:
                step = abs(step)
            if step > step_max:
                self.abort(0.0, FAULT_VELOCITY_LIMIT)
                return True
            prev = value
        return False
