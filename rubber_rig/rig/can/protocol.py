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

"""The rig's CAN protocol: the DBC shipped with the package, encode/decode with cantools, CRC-8 and
sequence-number unwrapping. Both ends (driver and simulated controller) use this module.
"""
import math
from pathlib import Path

import can
import cantools

from .codec import ByteCodec, crc8

DBC_PATH = Path(__file__).with_name('rubber_rig.dbc')
# The DBC is the one definition of the protocol: states, command codes, fault bits and frame periods are read
# from its VAL_ tables and GenMsgCycleTime attributes here (test_rig_protocol checks RigStatus.msg agrees).
_DBC = cantools.database.load_file(str(DBC_PATH))


def _choices(message: str, signal: str) -> dict[int, str]:
    return {int(value): str(name) for value, name in _DBC.get_message_by_name(message).get_signal_by_name(signal)
            .choices.items()}


def cycle_time(message: str) -> float:
    """Transmission period [s] of a periodic DBC message (GenMsgCycleTime); ValueError if it has none."""
    ms = _DBC.get_message_by_name(message).cycle_time
    if not ms:
        raise ValueError(f'{DBC_PATH.name}: message {message} has no GenMsgCycleTime')
    return ms / 1000.0


# RigStatus STATE_* (index = value), from VAL_ ST_State (HB_State repeats it)
STATES = tuple(name for _, name in sorted(_choices('ControllerStatus', 'ST_State').items()))
STATE_CODE = {name: i for i, name in enumerate(STATES)}

# RigStatus FAULT_* bits, from VAL_ ST_Faults (one entry per bit)
FAULT_NAMES = _choices('ControllerStatus', 'ST_Faults')
_FAULT_BIT = {name: bit for bit, name in FAULT_NAMES.items()}
FAULT_NONE = 0
FAULT_WATCHDOG = _FAULT_BIT['watchdog']
FAULT_DISPLACEMENT_LIMIT = _FAULT_BIT['displacement_limit']
FAULT_VELOCITY_LIMIT = _FAULT_BIT['velocity_limit']
FAULT_FORCE_LIMIT = _FAULT_BIT['force_limit']
FAULT_CONTROLLER = _FAULT_BIT['controller']
FAULT_SENSOR = _FAULT_BIT['sensor']
FAULT_BUS = _FAULT_BIT['bus']
FAULT_STREAM = _FAULT_BIT['stream']

# HostCommand codes, from VAL_ CMD_Code
_CMD = {name: code for code, name in _choices('HostCommand', 'CMD_Code').items()}
CMD_NOP, CMD_ENABLE, CMD_ABORT = _CMD['NOP'], _CMD['ENABLE'], _CMD['ABORT']
CMD_RESET, CMD_DISABLE, CMD_HOLD = _CMD['RESET'], _CMD['DISABLE'], _CMD['HOLD']
CMD_IDENTIFY = _CMD['IDENTIFY']

# the protocol version: the number in the DBC's VERSION "rubber_rig N"; a controller states the one it implements
# in ControllerIdentity.CI_Protocol, and the host streams only to a controller of the same version
PROTOCOL_VERSION = int(str(_DBC.version).rsplit(' ', 1)[-1])

# sequence numbers are the sample index modulo 2**bits of SP_Sequence (single-sample frames) and of
# ST_LastSequence (status); the packed frames have their own (rubber_rig.rig.can.frames)
SEQ_MOD = 1 << _DBC.get_message_by_name('Setpoint').get_signal_by_name('SP_Sequence').length
STATUS_SEQ_MOD = 1 << _DBC.get_message_by_name('ControllerStatus').get_signal_by_name('ST_LastSequence').length


# a Temperature frame without a reading (docs/protocol.md "Feedback"): TEMP_Specimen's lowest raw value, below
# absolute zero (-327.68 degC); the host reads it as no temperature (NaN)
_TEMP = _DBC.get_message_by_name('Temperature').get_signal_by_name('TEMP_Specimen')
TEMPERATURE_NOT_AVAILABLE = -(1 << (_TEMP.length - 1)) * _TEMP.scale + _TEMP.offset


def temperature_reading(value: float) -> float:
    """TEMP_Specimen [degC] as read, NaN for TEMPERATURE_NOT_AVAILABLE (no reading)."""
    return math.nan if value <= TEMPERATURE_NOT_AVAILABLE + 0.5 * _TEMP.scale else float(value)


def fault_names(mask: int) -> list[str]:
    """Names of the fault bits set in mask, lowest bit first."""
    return [name for bit, name in sorted(FAULT_NAMES.items()) if mask & bit]


def unwrap(seq: int, reference: int, modulus: int) -> int:
    """Full sample index for a sequence number `seq` (index mod modulus), the value nearest to `reference`."""
    delta = (seq - reference) % modulus
    if delta >= modulus // 2:
        delta -= modulus
    return reference + delta


def meet(expected, first: int, n: int) -> tuple:
    """How a run of n contiguous samples from sequence `first` meets `expected`, the sequence due next (None:
    nothing due yet). Returns (late, lost): the first `late` of the run have slots already past (delayed or
    duplicated: counted, never used) and `lost` samples were skipped before it (a gap). The one rule by which the
    driver, the CAN-log reader and the simulated controller count late and lost samples.
    """
    if expected is None:
        return 0, 0
    return min(n, max(0, expected - first)), max(0, first - expected)


class MalformedFrame(ValueError):
    """A frame with a known identifier whose length or CRC is wrong."""


class Protocol:
    """Encoder/decoder for the frames of rubber_rig.dbc: the layout of each message read from the DBC by cantools
    once, the packing done by codec.ByteCodec (the same bytes and values as cantools, test_rig_codec); a message
    ByteCodec cannot represent is packed by cantools itself.

    Every message ends with an 8-bit CRC signal (checked when the DBC is loaded) that this class fills in and
    verifies.
    """

    def __init__(self, dbc_path=DBC_PATH):
        self.db = _DBC if Path(dbc_path) == DBC_PATH else cantools.database.load_file(str(dbc_path))
        self.by_name = {m.name: m for m in self.db.messages}
        self.by_id = {m.frame_id: m for m in self.db.messages}
        for m in self.db.messages:
            crc = m.signals[-1]
            if not (crc.name.endswith('_Crc') and crc.start == 8 * (m.length - 1) and crc.length == 8):
                raise ValueError(f'{dbc_path}: message {m.name}: last signal must be an 8-bit CRC in the last byte')
        self._crc_name = {m.name: m.signals[-1].name for m in self.db.messages}
        self._codecs = {}
        for m in self.db.messages:
            try:
                self._codecs[m.frame_id] = self._codecs[m.name] = ByteCodec(m)
            except ValueError:
                pass            # cantools packs it

    def encode(self, name: str, signals: dict) -> can.Message:
        """A python-can Message for DBC message `name` with physical signal values (SI, as in the DBC)."""
        m = self.by_name[name]
        signals[self._crc_name[name]] = 0
        codec = self._codecs.get(name)
        if codec is not None:
            data = codec.encode([signals[n] for n in codec.names])
        else:
            data = bytearray(m.encode(signals, scaling=True, strict=False))
            data[-1] = crc8(m.frame_id, data[:-1])
        return can.Message(arbitration_id=m.frame_id, data=data, is_extended_id=False, is_fd=m.is_fd,
                           bitrate_switch=m.is_fd, check=False)

    def decode(self, msg: can.Message):
        """(name, signals) for a known frame; None for an unknown identifier; MalformedFrame if the length or
        CRC is wrong (corrupted frame).
        """
        m = self.by_id.get(msg.arbitration_id)
        if m is None or msg.is_extended_id or msg.is_error_frame or msg.is_remote_frame:
            return None
        data = bytes(msg.data)
        if len(data) != m.length:
            raise MalformedFrame(f'{m.name}: {len(data)} bytes instead of {m.length}')
        codec = self._codecs.get(m.frame_id)
        if codec is None:
            if crc8(m.frame_id, data[:-1]) != data[-1]:
                raise MalformedFrame(f'{m.name}: CRC mismatch')
            return m.name, m.decode(data, decode_choices=False, scaling=True)
        frame = codec.unpack(data)
        if frame is None:
            raise MalformedFrame(f'{m.name}: CRC mismatch')
        signals = dict(zip(codec.names, codec.fields(frame), strict=True))
        signals[codec.crc_name] = data[-1]
        return m.name, signals
