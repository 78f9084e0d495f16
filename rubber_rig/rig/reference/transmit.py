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

"""The frames the reference controller sends: status, heartbeat, temperature, identity (each counted as the
DBC's counters require) and feedback in the frame profile configured, with the transmit defects of defects.py.
"""
from __future__ import annotations

import can

PACK_MAX = 6                # samples per FeedbackPacked (FBP_Count 1-6)
DEVICE = 0x5246             # CI_Device of the reference controller ('RF')
FIRMWARE = 1
TEMPERATURE_NOT_AVAILABLE = -327.68   # [degC] TEMP_Specimen's lowest raw value: no reading (docs/protocol.md)


def swap_bytes_16(value: float, scale: float, signed: bool) -> float:
    """`value` sent with the two bytes of its 16-bit raw value swapped (defects: what a host then reads)."""
    raw = int(round(value / scale)) & 0xFFFF
    raw = ((raw & 0xFF) << 8) | (raw >> 8)
    if signed and raw & 0x8000:
        raw -= 0x10000
    return raw * scale


class FrameSender:
    """Encodes and sends the controller's frames on `bus` with `wire`'s layouts; `defects`: names of
    defects.REFERENCE_DEFECTS. Send errors (a full transmit queue) are counted in counters['tx_dropped'].
    """

    def __init__(self, bus: can.BusABC, wire, feedback_names: tuple, defects: frozenset, counters: dict):
        self.bus, self.wire, self.feedback_names, self.defects = bus, wire, feedback_names, defects
        self.counters = counters
        self.counter = {'ControllerStatus': 0, 'ControllerHeartbeat': 0, 'Temperature': 0}

    def send(self, name: str, values: dict):
        try:
            self.bus.send(self.wire.by_name[name].encode(values))
        except can.CanError:
            self.counters['tx_dropped'] += 1

    def _count(self, name: str, modulus: int) -> int:
        self.counter[name] = (self.counter[name] + 1) % modulus
        return self.counter[name]

    def status(self, state: str, faults: int, last_taken: int, level: int):
        self.send('ControllerStatus', {'ST_State': self.wire.state_code[state],
                                       'ST_Counter': self._count('ControllerStatus', 16), 'ST_Faults': faults,
                                       'ST_LastSequence': last_taken % (1 << 16), 'ST_BufferLevel': min(level, 65535)})

    def heartbeat(self, state: str):
        if 'no_heartbeat' not in self.defects:
            self.send('ControllerHeartbeat', {'HB_Counter': self._count('ControllerHeartbeat', 256),
                                              'HB_State': self.wire.state_code[state]})

    def temperature(self, ambient):
        value = TEMPERATURE_NOT_AVAILABLE if ambient is None else float(ambient)
        if 'temperature_byte_swapped' in self.defects and ambient is not None:
            value = swap_bytes_16(value, 0.01, True)
        self.send('Temperature', {'TEMP_Specimen': value, 'TEMP_Counter': self._count('Temperature', 256)})

    def identity(self, version: int, host_timeout: float, velocity_max: float):
        stated = 5.0 if 'rated_velocity_5ms' in self.defects else velocity_max
        if 'rated_velocity_byte_swapped' in self.defects:
            stated = swap_bytes_16(stated, 1e-4, False)
        self.send('ControllerIdentity', {'CI_Protocol': version, 'CI_Device': DEVICE, 'CI_Firmware': FIRMWARE,
                                         'CI_HostTimeout': min(host_timeout, 2.55), 'CI_VelocityMax': stated})

    def feedback(self, samples: list, final: bool) -> list:
        """Send `samples` [(sequence, x, force, u)]; returns those held back for a later frame (defect
        feedback_six_per_frame: until 6 are there, unless `final`, the last ticks before the controller rests).
        """
        name = self.feedback_names[0]
        if name == 'FeedbackPacked':
            if 'feedback_six_per_frame' in self.defects and not final:
                keep = len(samples) % PACK_MAX
                samples, held = samples[:len(samples) - keep], samples[len(samples) - keep:]
            else:
                held = []
            for i in range(0, len(samples), PACK_MAX):
                chunk = samples[i:i + PACK_MAX]
                values = {'FBP_Sequence': chunk[0][0] % (1 << 32), 'FBP_Count': len(chunk)}
                for j, (_, x, force, u) in enumerate(chunk):
                    values.update({f'FBP_Displacement_{j}': x, f'FBP_Force_{j}': force, f'FBP_Setpoint_{j}': u})
                self.send(name, values)
            return held
        for seq, x, force, u in samples:
            if name == 'Feedback':
                self.send(name, {'FB_Sequence': seq % (1 << 16), 'FB_Displacement': x, 'FB_Force': force,
                                 'FB_Setpoint': u})
            else:
                self.send('FeedbackApplied', {'FA_Sequence': seq % (1 << 16), 'FA_Setpoint': u})
                self.send('FeedbackMeasured', {'FM_Sequence': seq % (1 << 8), 'FM_Displacement': x,
                                               'FM_Force': force})
        return []
