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

"""Conformance scenarios of what a controller must refuse or survive: corrupt and foreign frames, the host's
limits, setpoints out of limits or too fast, a silent host and the sequence wrap (mixed into
active.ConformanceRun).
"""
from __future__ import annotations

import math
import time

import can

from ..can.protocol import (
    CMD_ABORT,
    CMD_RESET,
    FAULT_DISPLACEMENT_LIMIT,
    FAULT_VELOCITY_LIMIT,
    FAULT_WATCHDOG,
    fault_names,
    unwrap,
)
from .link import (
    LEAD,
    LSB,
    RAMP_VELOCITY,
    REST_TIMEOUT,
    ConformanceLink,
)
from .report import FAIL, NOT_TESTED, PASS


class FaultScenarios(ConformanceLink):
    """The scenarios of faults and bad input."""

    def s_bad_frames(self):
        """Malformed and foreign frames while running (CTRL-FRAME-2, CTRL-FRAME-3)."""
        a = 0.2 * self.env.half
        p0 = self.position
        first = self.next_sequence() + 1000
        wild = 20e-6
        injected = {}
        phase = {}

        def inject(k):
            seq = first + k - int(LEAD * self.fs / 2)          # sent, and still queued at the controller
            good = self.sent.get(seq)
            if good is None:
                return
            if k == int(0.3 * self.fs):
                phase['frame2'] = time.time()
                msg = self.frames.encode_setpoints(seq, [good + wild])[0]
                data = bytearray(msg.data)
                data[-1] ^= 0x5A
                self._tx(can.Message(arbitration_id=msg.arbitration_id, data=data, is_fd=msg.is_fd,
                                     bitrate_switch=msg.bitrate_switch, is_extended_id=False, check=False))
                injected[seq] = 'CTRL-FRAME-2'
                msg = self.frames.encode_setpoints(seq + 1, [good + wild])[0]
                self._tx(can.Message(arbitration_id=msg.arbitration_id, data=bytes(msg.data[:len(msg.data) // 2]),
                                     is_fd=msg.is_fd, is_extended_id=False, check=False))
                injected[seq + 1] = 'CTRL-FRAME-2'
                bad = self.proto.encode('HostCommand', {'CMD_Code': CMD_ABORT, 'CMD_Counter': 0,
                                                        'CMD_Argument': 0.0, 'CMD_RampVelocity': 0.0})
                bad.data = bytearray(bad.data)
                bad.data[-1] ^= 0xFF
                self._tx(bad)
            elif k == int(0.7 * self.fs):
                phase['frame3'] = time.time()
                msg = self.frames.encode_setpoints(seq, [good + wild])[0]
                self._tx(can.Message(arbitration_id=msg.arbitration_id, data=msg.data, is_fd=msg.is_fd,
                                     bitrate_switch=msg.bitrate_switch, is_extended_id=True, check=False))
                injected[seq] = 'CTRL-FRAME-3'
                abort = self.proto.encode('HostCommand', {'CMD_Code': CMD_ABORT, 'CMD_Counter': 0,
                                                          'CMD_Argument': 0.0, 'CMD_RampVelocity': 0.0})
                self._tx(can.Message(arbitration_id=abort.arbitration_id, data=abort.data, is_extended_id=True))
                self._tx(can.Message(arbitration_id=abort.arbitration_id, is_remote_frame=True, dlc=8,
                                     is_extended_id=False))
                self._tx(can.Message(arbitration_id=0x7FE, data=bytes(8), is_extended_id=False))

        base = self.smooth(p0, -a if p0 > 0 else a)

        def wave(k):
            inject(k)
            return base(k)
        end = self.stream(first, wave, 1.1)
        self._sleep(LEAD + 0.05)
        samples = [s for s in self._samples_since(phase.get('frame2', 0.0)) if s.seq < end]
        for rid, since, until in (('CTRL-FRAME-2', 'frame2', 'frame3'), ('CTRL-FRAME-3', 'frame3', None)):
            t0, t1 = phase.get(since, math.inf), phase.get(until, math.inf) if until else math.inf
            applied_wrong = [seq for seq, who in injected.items() if who == rid and any(
                s.seq == seq and abs(s.u - self.sent[seq]) > 1.5 * LSB for s in samples)]
            stopped = [s for s in self._states_since(t0) if s[0] < t1 and s[1] != 'running'
                       and unwrap(s[3], end, 1 << 16) < end - 1]
            ok = not applied_wrong and not stopped and bool(samples)
            self.results.put(rid, PASS if ok else FAIL, f'{len(applied_wrong)} injected setpoints applied, '
                             f'{len(stopped)} status frames out of running',
                             '' if ok else 'such frames must change nothing')
        self.to_rest(self.position)

    def s_host_limits(self):
        """HostLimits bound the controller's own ramp (CTRL-LIM-1)."""
        hl_max = 0.5 * self.env.upper
        self.limits(self.env.lower, hl_max)
        p0 = min(self.position, 0.0)
        first = self.next_sequence() + 1000
        self.stream(first, self.ramp_to(self.position, p0, RAMP_VELOCITY), 0.2)
        self._sleep(LEAD + 0.1)
        t = time.time()
        target = 0.9 * self.env.upper
        self.command(CMD_ABORT, target, 5 * RAMP_VELOCITY)
        self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT)
        self._sleep(0.05)
        u = [s.u for s in self._samples_since(t)]
        top = max(u, default=self.position)
        ok = bool(u) and top <= hl_max + 1.5 * LSB and abs(u[-1] - hl_max) <= 1e-6
        self.results.put('CTRL-LIM-1', PASS if ok else FAIL,
                         f'ABORT to {target * 1e3:.4f} mm with HL_DisplacementMax {hl_max * 1e3:.4f} mm: highest '
                         f'{top * 1e3:.4f} mm, stopped at {u[-1] * 1e3 if u else math.nan:.4f} mm',
                         '' if ok else "the controller's ramp must stop at HL_DisplacementMax")
        self.to_rest(self.position)

    def s_out_of_limits(self):
        """A setpoint outside HostLimits (CTRL-LIM-2, CTRL-FAULT-1, CTRL-FAULT-2)."""
        hl_max = 0.5 * self.env.upper
        self.limits(self.env.lower, hl_max)
        first = self.next_sequence() + 1000
        target = 0.8 * self.env.upper
        p0 = self.position
        t = time.time()
        try:
            self.stream(first, self.ramp_to(p0, target, RAMP_VELOCITY), abs(target - p0) / RAMP_VELOCITY + 0.1)
        finally:
            self.heartbeat = True
        self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT)
        self._sleep(0.05)
        u = [s.u for s in self._samples_since(t)]
        top = max(u, default=p0)
        faults = self._fault_bits_since(t)
        ok = top <= hl_max + 1.5 * LSB and bool(faults) and self.state == 'fault'
        self.results.put('CTRL-LIM-2', PASS if ok else FAIL,
                         f'setpoints up to {target * 1e3:.4f} mm with HL_DisplacementMax {hl_max * 1e3:.4f} mm: '
                         f'highest applied {top * 1e3:.4f} mm, faults {fault_names(faults)}, state {self.state}',
                         '' if ok else 'a setpoint beyond HostLimits must never be applied, and must fault the rig')
        self._judge_fault_bits('outside HostLimits', faults, FAULT_DISPLACEMENT_LIMIT)
        self._judge_latch()
        self.limits(self.env.lower, self.env.upper)
        self.to_rest(self.position)

    def _fault_bits_since(self, t: float) -> int:
        bits = 0
        for s in self._states_since(t):
            bits |= s[2]
        return bits

    def _judge_fault_bits(self, cause: str, bits: int, expected: int):
        """CTRL-FAULT-1: judged only where a fault was raised (a missing fault fails the scenario's own
        requirement).
        """
        if not bits:
            return
        ok = bits == expected
        self.results.put('CTRL-FAULT-1', PASS if ok else FAIL, f'{cause}: {fault_names(bits)}',
                         '' if ok else f'expected exactly {fault_names(expected)}')

    def _judge_latch(self):
        """CTRL-FAULT-2: the fault stays until RESET; RESET returns to idle without fault bits."""
        if self.state != 'fault':
            return
        t = time.time()
        self._sleep(0.3)
        latched = all(s[1] == 'fault' and s[2] for s in self._states_since(t))
        t_reset = time.time()
        self.command(CMD_RESET)
        cleared = self._wait(lambda: self.state == 'idle' and not self.faults, 0.2)
        self.results.put('CTRL-FAULT-2', PASS if latched and cleared else FAIL,
                         f'fault held 0.3 s: {latched}; idle without faults {time.time() - t_reset:.3f} s after RESET: '
                         f'{cleared}', '' if latched and cleared else 'a fault must latch until RESET, which clears it')

    def s_too_fast(self):
        """A setpoint faster than the rated velocity (CTRL-LIM-3, CTRL-FAULT-1)."""
        if not self.identity or float(self.identity[1]['CI_VelocityMax']) <= 0:
            self.results.put('CTRL-LIM-3', NOT_TESTED, '', 'the controller states no rated velocity')
            return
        vmax = float(self.identity[1]['CI_VelocityMax'])
        step = 1.5 * vmax / self.fs
        p0 = self.position
        end_pos = p0 + step if p0 + step <= 0.8 * self.env.upper else p0 - step
        if not 0.8 * self.env.lower <= end_pos <= 0.8 * self.env.upper:
            self.results.put('CTRL-LIM-3', NOT_TESTED, f'a step of {step * 1e3:.3f} mm is needed',
                             'the envelope is too small for a step above the rated velocity')
            return
        first = self.next_sequence() + 1000
        t = time.time()
        self.stream(first, lambda k: p0 if k < int(0.2 * self.fs) else end_pos, 0.4)
        self.heartbeat = True
        self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT)
        self._sleep(0.05)
        u = [p0] + [s.u for s in self._samples_since(t)]
        fastest = max((abs(b - a) * self.fs for a, b in zip(u, u[1:], strict=False)), default=0.0)
        faults = self._fault_bits_since(t)
        ok = fastest <= vmax * 1.02 + 2 * LSB * self.fs and bool(faults) and self.state == 'fault'
        self.results.put('CTRL-LIM-3', PASS if ok else FAIL,
                         f'a step of {step * 1e3:.3f} mm in one sample ({step * self.fs:.3f} m/s, rated '
                         f'{vmax:g} m/s): fastest applied {fastest:.4f} m/s, faults {fault_names(faults)}',
                         '' if ok else 'a setpoint above the rated velocity must never be applied, and must fault')
        self._judge_fault_bits('too fast', faults, FAULT_VELOCITY_LIMIT)
        self.to_rest(self.position)

    def s_host_silence(self):
        """Host silence (CTRL-WD-1, CTRL-FAULT-1)."""
        a = 0.4 * self.env.half
        p0 = self.position
        first = self.next_sequence() + 1000
        self.stream(first, self.smooth(p0, -a if p0 > 0 else a), 0.6)
        self.heartbeat = False
        self._sleep(0.01)
        with self.lock:   # the controller's host watchdog runs on HostHeartbeat
            t_silent = max(f.t for f in self.trace.frames if f.name == 'HostHeartbeat')
        timeout = self.host_timeout
        ramped = self._wait(lambda: self.state in ('ramping_down', 'fault', 'idle'), timeout + 1.0)
        t_ramp = next((s[0] for s in self._states_since(t_silent) if s[1] in ('ramping_down', 'fault', 'idle')),
                      None)
        if not ramped:
            self.results.put('CTRL-WD-1', FAIL, f'still {self.state} {timeout + 1.0:.2f} s after the host fell silent '
                             f'(stated host timeout {timeout:g} s)', 'the controller must ramp to rest on host silence')
            self.to_rest(0.0)
            return
        self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT)
        self._sleep(0.05)
        delay = t_ramp - t_silent
        faults = self._fault_bits_since(t_silent)
        rest = self.position
        ok = delay <= timeout + 0.1 and abs(rest) <= 1e-6 and self.state == 'fault' and bool(faults)
        self.results.put('CTRL-WD-1', PASS if ok else FAIL,
                         f'ramp began {delay:.3f} s after the last HostHeartbeat (stated host timeout {timeout:g} s), '
                         f'rest at {rest * 1e3:.4f} mm, state {self.state}, faults {fault_names(faults)}',
                         '' if ok else 'host silence must ramp the rig to rest within the host timeout, faulted')
        self._judge_fault_bits('host silence', faults, FAULT_WATCHDOG)
        self.to_rest(0.0)

    def s_wrap(self):
        """Streams across a 2^16 boundary and the field's wrap (CTRL-SEQ-2)."""
        starts = [(1 << 16) - int(0.3 * self.fs)]
        if self.trace.modulus[self.frames.feedback_names[0]] > (1 << 16):
            starts.append((1 << 32) - int(0.3 * self.fs))
        for first in starts:
            p0 = self.position
            self.stream(first, lambda k, p=p0: p, 0.6)
            self._sleep(LEAD + 0.1)
            self.to_rest(0.0)
