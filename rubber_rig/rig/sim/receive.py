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
setpoints (accepted in order, or refused and counted as a real controller would). The receiver changes the
controller's shared state (state.ControllerState) as the frames say; what they ask the controller to do - ramp
to rest, report its status now, identify itself - it asks of the controller through the callables it was given.
"""
import math
from typing import Callable

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
from .state import ControllerState


class CommandReceiver:
    """The receive side of the simulated controller: frames from `bus` decoded with `proto` and the sample frames
    `frames`, applied to `shared`. abort(target [m] or None, fault_bits, velocity_max [m/s] or None) ramps the
    controller to rest, report() sends its status now, identify() its ControllerIdentity; velocity_max [m/s] the
    actuator's rated velocity, fs [Hz] the sample rate; defects: deliberate protocol defects (conformance testing).
    """

    def __init__(self, shared: ControllerState, bus, proto, frames, defects: frozenset, velocity_max: float,
                 fs: float, abort: Callable, report: Callable, identify: Callable):
        self.shared, self.bus, self.proto, self.frames, self.defects = shared, bus, proto, frames, defects
        self.velocity_max, self.fs = velocity_max, fs
        self._abort, self._report, self._identify = abort, report, identify
        self.setpoint_ids = {self.frames.codecs[n].frame_id for n in self.frames.setpoint_names}
        self._identified = False          # defect identify_answered_once: IDENTIFY was answered

    def is_setpoint(self, msg) -> bool:
        return msg.arbitration_id in self.setpoint_ids

    def receive_all(self):
        """Handle every frame waiting on the bus."""
        msg = self.bus.recv(0)
        while msg is not None:
            self.handle(msg)
            msg = self.bus.recv(0)

    def handle(self, msg):
        """One frame from the host."""
        if msg.arbitration_id in self.setpoint_ids and not msg.is_extended_id:
            self._on_setpoints(msg)
            return
        try:
            decoded = self.proto.decode(msg)
        except MalformedFrame:   # CTRL-FRAME-2: counted, never applied
            self.shared.counters['frames_bad'] += 1
            decoded = self._unchecked_host_limits(msg)
            if decoded is None:
                return
        if decoded is None:      # CTRL-FRAME-3: unknown, extended, remote frames change nothing
            return
        name, sig = decoded
        sh = self.shared
        if name == 'HostStreamStart':
            sh.accept_from = int(sig['HS_FirstSequence'])
        elif name == 'HostHeartbeat':
            sh.last_host_hb = sh.ticks
        elif name == 'HostLimits' and 'ignore_host_limits' not in self.defects:   # CTRL-LIM-1
            self._on_limits(float(sig['HL_DisplacementMin']), float(sig['HL_DisplacementMax']),
                            float(sig['HL_Deceleration']))
        elif name == 'HostCommand':
            self._on_command(int(sig['CMD_Code']), float(sig['CMD_Argument']), float(sig['CMD_RampVelocity']))

    def _on_limits(self, lo: float, hi: float, decel: float):
        sh = self.shared
        if lo < hi:
            # defect ignore_lower_limit: only the upper bound is kept (the downward direction never checked)
            sh.lower = -math.inf if 'ignore_lower_limit' in self.defects else lo
            sh.upper = hi
            sh.decel_max = decel or DECEL_MAX
            self._refuse_queued()
        else:                    # min >= max: discarded whole, the limits stay as they were
            sh.counters['frames_bad'] += 1

    def _on_command(self, code: int, argument: float, ramp_velocity: float):
        sh = self.shared
        if code == CMD_DISABLE and 'ignore_disable' in self.defects:
            pass
        elif code in (CMD_ABORT, CMD_DISABLE):
            self._abort(argument, 0, ramp_velocity or None)
        elif code == CMD_HOLD:
            self._abort(None, 0, ramp_velocity or None)
        elif code == CMD_IDENTIFY:
            if 'identify_answered_once' not in self.defects or not self._identified:
                self._identify()    # CTRL-ID-1
            self._identified = True
        elif code == CMD_RESET and (sh.state in ('fault', 'idle') or (   # CTRL-FAULT-2; CTRL-RESET-1
                'reset_while_ramping' in self.defects and sh.state == 'ramping_down')):
            sh.fault_bits = 0
            sh.state = 'idle'
            self._report()

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
        sh = self.shared
        try:
            seq, values = self.frames.decode_setpoints(msg)
        except MalformedFrame:
            sh.counters['frames_bad'] += 1
            return
        if sh.state in ('ramping_down', 'fault'):
            return
        if sh.state == 'idle':   # CTRL-STREAM-1, CTRL-STREAM-2: only from HS_FirstSequence on
            seq = unwrap(seq, sh.accept_from if math.isfinite(sh.accept_from) else sh.next_seq,
                         self.frames.setpoint_modulus)
            if seq < sh.accept_from:   # left over from an aborted stream, or no stream announced
                sh.counters['setpoints_stale'] += 1
                return
        else:
            seq = unwrap(seq, sh.next_seq, self.frames.setpoint_modulus)
        if sh.state == 'idle':
            sh.buffer.clear()
            sh.next_seq = seq
            sh.state = 'running'
            sh.last_host_hb = sh.ticks
            self._report()
        late, _ = meet(sh.next_seq, seq, len(values))   # a gap ahead is bridged by holding (CTRL-STREAM-3)
        sh.counters['setpoints_late'] += late
        if self._refuse_setpoints(seq, late, values):
            return
        if len(sh.buffer) < self.frames.setpoint_modulus // 2:
            buffer = sh.buffer
            for i in range(late, len(values)):
                buffer[seq + i] = values[i]

    def _refuse_queued(self):
        """CTRL-LIM-2: HostLimits that tighten while setpoints are queued bind those too: one outside the new limits
        is refused as if it had just arrived (flush, ramp to rest, displacement_limit).
        """
        sh, tol = self.shared, LSB + 1e-12
        if sh.state in ('running', 'holding') and any(
                not sh.lower - tol <= v <= sh.upper + tol for v in sh.buffer.values()):
            self._abort(0.0, FAULT_DISPLACEMENT_LIMIT)

    def _refuse_setpoints(self, seq: int, late: int, values) -> bool:
        """CTRL-LIM-2 / CTRL-LIM-3: a setpoint outside the host's limits, or one that steps faster than the rated
        velocity from the setpoint before it, is never applied: the controller faults and ramps to rest. True if
        the batch was refused.
        """
        sh, tol = self.shared, LSB + 1e-12
        step_max = (self.velocity_max * 1.02) / self.fs + 2 * LSB
        prev = sh.buffer.get(seq + late - 1)
        if prev is None and seq + late == sh.next_seq:
            prev = sh.u
        for i in range(late, len(values)):
            value = values[i]
            if not sh.lower - tol <= value <= sh.upper + tol:
                self._abort(0.0, FAULT_DISPLACEMENT_LIMIT)
                return True
            step = value - prev if prev is not None else 0.0
            if 'velocity_check_upward_only' not in self.defects:
                step = abs(step)
            if step > step_max:
                self._abort(0.0, FAULT_VELOCITY_LIMIT)
                return True
            prev = value
        return False
