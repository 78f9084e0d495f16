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

"""The reference controller's view of the bus, written from the DBC alone: frame layouts read from
``rubber_rig.dbc`` with cantools, packed and unpacked by its own bit arithmetic, and its own CRC-8 (SAE J1850,
docs/protocol.md "Conventions"). Deliberately shares no code with the host's codec (rig/can/codec.py,
frames.py) nor the simulator (rig/sim/): a misreading of the specification in either would show up as a
disagreement in a conformance run, not be copied.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import can
import cantools

DBC_FILE = Path(__file__).resolve().parents[1] / 'can' / 'rubber_rig.dbc'


def crc8_j1850(frame_id: int, payload: bytes) -> int:
    """CRC-8 SAE J1850 (polynomial 0x1D, initial 0xFF, final XOR 0xFF) over the 11-bit identifier as two bytes,
    little endian, then `payload` (docs/protocol.md "CRC"). Bitwise, as the specification states it.
    """
    crc = 0xFF
    for byte in bytes((frame_id & 0xFF, (frame_id >> 8) & 0xFF)) + bytes(payload):
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


@dataclass(frozen=True)
class Field:
    """One signal: start bit (Intel), length [bits], signed, scale and offset (physical = raw x scale + offset)."""

    start: int
    length: int
    signed: bool
    scale: float
    offset: float

    def pack(self, value: float) -> int:
        raw = int(round((value - self.offset) / self.scale))
        top = 1 << (self.length - 1)
        lo, hi = (-top, top - 1) if self.signed else (0, 2 * top - 1)
        raw = min(max(raw, lo), hi)
        return (raw & ((1 << self.length) - 1)) << self.start

    def unpack(self, word: int) -> float:
        raw = (word >> self.start) & ((1 << self.length) - 1)
        if self.signed and raw & (1 << (self.length - 1)):
            raw -= 1 << self.length
        return raw * self.scale + self.offset


class Layout:
    """One DBC message: identifier, length, FD or not, period [s] (None: not periodic) and its fields by name."""

    def __init__(self, message):
        self.name, self.frame_id, self.length = message.name, message.frame_id, message.length
        self.is_fd = bool(message.is_fd) or message.length > 8
        self.period = message.cycle_time / 1000.0 if message.cycle_time else None
        self.fields = {s.name: Field(s.start, s.length, bool(s.is_signed), float(s.scale), float(s.offset))
                       for s in message.signals}
        self.crc_name = message.signals[-1].name

    def encode(self, values: dict) -> can.Message:
        """A frame with `values` (physical, by signal name; others 0) and its CRC in the last byte."""
        word = 0
        for name, value in values.items():
            word |= self.fields[name].pack(value)
        data = bytearray(word.to_bytes(self.length, 'little'))
        data[-1] = crc8_j1850(self.frame_id, data[:-1])
        return can.Message(arbitration_id=self.frame_id, data=data, is_extended_id=False, is_fd=self.is_fd,
                           bitrate_switch=self.is_fd)

    def decode(self, data: bytes) -> dict | None:
        """Physical values by signal name, or None when the length or the CRC is wrong (malformed)."""
        if len(data) != self.length or crc8_j1850(self.frame_id, data[:-1]) != data[-1]:
            return None
        word = int.from_bytes(bytes(data), 'little')
        return {name: f.unpack(word) for name, f in self.fields.items() if name != self.crc_name}


class Wire:
    """Every message of the DBC by name and by identifier, the protocol version and the value tables the
    controller needs (states, fault bits, command codes).
    """

    def __init__(self, path: Path = DBC_FILE):
        db = cantools.database.load_file(str(path))
        self.version = int(str(db.version).rsplit(' ', 1)[-1])
        self.by_name = {m.name: Layout(m) for m in db.messages}
        self.by_id = {m.frame_id: self.by_name[m.name] for m in db.messages}
        self.host_ids = {m.frame_id for m in db.messages if 'HOST' in m.senders}

        def table(message, signal):
            return {str(v): int(k) for k, v in db.get_message_by_name(message).get_signal_by_name(signal)
                    .choices.items()}
        self.state_code = table('ControllerStatus', 'ST_State')
        self.fault_bit = table('ControllerStatus', 'ST_Faults')
        self.command_code = table('HostCommand', 'CMD_Code')

    def host_frame(self, msg: can.Message):
        """(layout, signals) of a well-formed host frame; (layout, None) for a malformed one of a host identifier;
        None for anything foreign: extended, remote or error frames, identifiers the DBC does not define or whose
        sender is the controller (CTRL-FRAME-3).
        """
        if msg.is_extended_id or msg.is_error_frame or msg.arbitration_id not in self.host_ids:
            return None
        layout = self.by_id[msg.arbitration_id]
        if msg.is_remote_frame:
            return layout, None
        return layout, layout.decode(bytes(msg.data))
