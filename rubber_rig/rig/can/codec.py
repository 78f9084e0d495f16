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


"""Fast encode/decode of the rig's per-sample frames, derived from their DBC definition.

cantools builds a dict per frame and (through python-can) a deep copy per send: tens of microseconds per frame,
more than the element model costs per sample. Every signal of rubber_rig.dbc is a little-endian integer with a
scale and an offset, so :class:`ByteCodec` reads the layout (start bit, length, sign, scale, offset) from the
cantools Message once and packs a frame as one integer (each field shifted to its start bit; a payload of n
bytes is the integer's n-byte little-endian form). cantools stays the definition: a codec refuses a message it
cannot represent exactly, and test_rig_codec checks both agree on every field of every message.

The CRC-8 of a frame is affine over GF(2) in its payload bits (crc(a ^ b) = crc(a) ^ crc(b) ^ crc(0) for equal
lengths), so :class:`ByteCodec` derives, once per message, the CRC of the all-zero payload and for each of the 8
CRC bits the mask of payload bits whose parity flips it: a frame's CRC is then 8 AND-and-parity operations on
its payload integer instead of a table lookup per byte; test_rig_codec checks it against :func:`crc8`.

A frame of samples is encoded and decoded once per sample on each side of a simulated rig, so the per-signal loops
are compiled once per layout (:func:`_compile`): each signal's step written out with its constants, the same
operations in the same order as the loop they replace (the same ints and floats, to the bit), without the loop's
zip, tuple unpacking and attribute look-ups.
"""
from __future__ import annotations

__all__ = ['ByteCodec', 'crc8']


def _crc8_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return table


_CRC_TABLE = _crc8_table()


def crc8(frame_id: int, payload) -> int:
    """CRC-8 SAE J1850 (poly 0x1D, init/xor 0xFF) over the identifier (2 bytes LE) and payload bytes."""
    table = _CRC_TABLE
    crc = table[0xFF ^ (frame_id & 0xFF)]
    crc = table[crc ^ ((frame_id >> 8) & 0xFF)]
    for b in payload:
        crc = table[crc ^ b]
    return crc ^ 0xFF


def _crc_masks(frame_id: int, nbytes: int) -> tuple[int, tuple]:
    """(crc8 of `nbytes` zero bytes, masks): bit j of crc8(frame_id, payload) is bit j of that constant XOR the
    parity of (payload as a little-endian integer) & masks[j].
    """
    zero = crc8(frame_id, bytes(nbytes))
    masks = [0] * 8
    for bit in range(8 * nbytes):
        unit = (1 << bit).to_bytes(nbytes, 'little')
        flips = crc8(frame_id, unit) ^ zero
        for j in range(8):
            if flips >> j & 1:
                masks[j] |= 1 << bit
    return zero, tuple(masks)


class ByteCodec:
    """Encoder/decoder of one DBC message whose signals are all little-endian integers and whose last byte is its
    CRC-8 (rubber_rig.dbc's convention).

    Values are physical (the DBC's units: m, N); raw = round((value - offset) / scale), saturated to the
    signal's integer range (a frame cannot carry more; the sender's own checks judge such a value).
    ValueError (naming the signal) for a message this codec cannot represent exactly.
    """

    _crc_cache: dict = {}

    def __init__(self, message):
        self.name, self.frame_id, self.length = message.name, message.frame_id, message.length
        self.is_fd = bool(message.is_fd)
        signals = message.signals[:-1]
        crc = message.signals[-1]
        if not (crc.name.endswith('_Crc') and crc.start == 8 * (self.length - 1) and crc.length == 8):
            raise ValueError(f'{self.name}: the last signal must be an 8-bit CRC in the last byte')
        self.crc_name, self._crc_bits = crc.name, crc.start
        self.names = [s.name for s in signals]
        self._layout = []        # per signal: (bit position, bit mask, sign bit (0: unsigned), scale, offset, lo, hi)
        for s in signals:
            if s.byte_order != 'little_endian' or s.is_float or s.multiplexer_ids \
                    or s.start + s.length > self._crc_bits:
                raise ValueError(f'{self.name}.{s.name}: not a little-endian integer signal before the CRC')
            lo, hi = (-(1 << (s.length - 1)), (1 << (s.length - 1)) - 1) if s.is_signed else (0, (1 << s.length) - 1)
            # scale and offset as the DBC gives them: an int scale decodes to ints, as cantools does
            self._layout.append((s.start, (1 << s.length) - 1, 1 << (s.length - 1) if s.is_signed else 0,
                                 s.scale, s.offset, lo, hi))
        self._integer = [sc == 1 and off == 0 for _, _, _, sc, off, _, _ in self._layout]
        # what fields() reads per signal: (bit position, mask, sign bit, scale, offset), None scale for a raw int
        pairs = zip(self._layout, self._integer, strict=True)
        self._read = [(shift, mask, sign, None if integer else scale, offset)
                      for (shift, mask, sign, scale, offset, _, _), integer in pairs]
        key = (self.frame_id, self.length)
        if key not in self._crc_cache:
            self._crc_cache[key] = _crc_masks(self.frame_id, self.length - 1)
        self._crc_zero, self._crc_masks = self._crc_cache[key]
        self._crc_shift = 8 * (self.length - 1)
        self._payload_mask = (1 << self._crc_shift) - 1
        self._crc = self._compile_crc()
        self._encoders, self._readers = {}, {}   # compiled by number of values, by (start, count)

    def crc(self, payload: int) -> int:
        """CRC-8 of the payload (all bytes but the CRC's) given as its little-endian integer; = crc8()."""
        return self._crc(payload)

    def encode(self, values) -> bytearray:
        """Payload (length bytes, CRC filled in) for physical `values` in the order of `names`; signals after
        the last value given are raw 0 (the unused slots of a packed frame).

        raw = round((value - offset) / scale), saturated to the signal's integer range, at its start bit.
        """
        encoder = self._encoders.get(len(values))
        if encoder is None:
            encoder = self._encoders[len(values)] = self._compile_encoder(min(len(values), len(self._layout)))
        return encoder(values if len(values) <= len(self._layout) else values[:len(self._layout)])

    def check(self, data) -> str:
        """'' if data has this message's length and a matching CRC, else what is wrong."""
        if len(data) != self.length:
            return f'{self.name}: {len(data)} bytes instead of {self.length}'
        return '' if self.unpack(data) is not None else f'{self.name}: CRC mismatch'

    def unpack(self, data):
        """The frame as one little-endian integer (fields() reads its signals), None if its length or CRC is
        wrong (check() says which).
        """
        if len(data) != self.length:
            return None
        frame = int.from_bytes(data, 'little')
        return frame if self.crc(frame & self._payload_mask) == frame >> self._crc_shift else None

    def fields(self, frame: int, count: int = None, start: int = 0) -> list:
        """Physical values (ints for unscaled integer signals) of the signals start, start + 1, ... up to `count`
        (default: all) of an unpacked frame.
        """
        reader = self._readers.get((start, count))
        if reader is None:
            reader = self._readers[start, count] = self._compile_reader(range(len(self._read))[start:count])
        return reader(frame)

    # ---- the compiled loops
    def _compile_crc(self):
        """crc(payload): the CRC of the all-zero payload XOR, per CRC bit, the parity of the payload's bits under
        that bit's mask (module docstring).
        """
        terms = ' ^ '.join(f'(((payload & {mask}).bit_count() & 1) << {j})' for j, mask in enumerate(self._crc_masks))
        return _compile(f'def crc(payload):\n    return {self._crc_zero} ^ {terms}\n', 'crc', {})

    def _compile_encoder(self, n: int):
        """encode() of exactly `n` values: each signal's raw value, saturated, shifted into place."""
        lines, names = ['def encode(values):'], {'crc': self._crc}
        if n:
            lines.append(f'    {", ".join(f"v{i}" for i in range(n))}, = values')
        lines.append('    payload = 0')
        for i, (shift, mask, _, scale, offset, lo, hi) in enumerate(self._layout[:n]):
            names[f'scale{i}'], names[f'offset{i}'] = scale, offset
            lines += [f'    raw = round((v{i} - offset{i}) / scale{i})',
                      f'    raw = {lo} if raw < {lo} else {hi} if raw > {hi} else raw',
                      f'    payload |= (raw & {mask}) << {shift}']
        lines.append(f'    return bytearray((payload | crc(payload) << {self._crc_shift}).to_bytes({self.length}, '
                     "'little'))")
        return _compile('\n'.join(lines) + '\n', 'encode', names)

    def _compile_reader(self, signals):
        """fields() of the signals `signals` (indices): each one's raw bits, sign-extended, scaled."""
        lines, names, out = ['def fields(frame):'], {}, []
        for i in signals:
            shift, mask, sign, scale, offset = self._read[i]
            lines.append(f'    raw{i} = frame >> {shift} & {mask}')
            if sign:
                lines.append(f'    if raw{i} & {sign}:\n        raw{i} -= {sign << 1}')
            if scale is None:
                out.append(f'raw{i}')
            else:
                names[f'scale{i}'], names[f'offset{i}'] = scale, offset
                out.append(f'raw{i} * scale{i} + offset{i}')
        lines.append(f'    return [{", ".join(out)}]')
        return _compile('\n'.join(lines) + '\n', 'fields', names)

    def decode(self, data, count: int = None) -> list:
        """Physical values (ints for unscaled integer signals) in the order of `names`, from one payload: all of
        them, or the first `count`.
        """
        return self.fields(int.from_bytes(data, 'little'), count)


_COMPILED: dict = {}     # (source, constants with their types) -> function: each layout is compiled once


def _compile(source: str, name: str, constants: dict):
    """The function `name` defined by `source`, with `constants` (scales and offsets, as the DBC gives them: an
    int stays an int) as its globals; compiled once per process for each source and constants.
    """
    key = (source, tuple((k, type(v), v) for k, v in sorted(constants.items())))
    function = _COMPILED.get(key)
    if function is None:
        namespace = dict(constants, __builtins__={'round': round, 'bytearray': bytearray})
        exec(compile(source, f'<ByteCodec {name}>', 'exec'), namespace)     # noqa: S102 (our own source)
        function = _COMPILED[key] = namespace[name]
    return function
