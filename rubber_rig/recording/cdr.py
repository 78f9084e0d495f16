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

"""Fast CDR decoding with numpy, generated from the ros2msg schema in the file (no rclpy).

mcap_ros2's dynamic decoder reads arrays one element at a time in Python (about 1.3 s per minute of
10 kHz samples); here numeric arrays are single ``np.frombuffer`` calls, which makes loading hours of
recordings practical. Only little-endian plain CDR (what ROS 2 Jazzy's DDS layers write) is handled;
anything else returns None and the caller uses mcap_ros2's decoder.
"""
import struct
from types import SimpleNamespace

import numpy as np

from .mcap_compat import for_each_msgdef

PRIMITIVES = {  # ros type -> (struct code, size, numpy dtype)
    'bool': ('?', 1, np.bool_), 'byte': ('B', 1, np.uint8), 'char': ('B', 1, np.uint8),
    'int8': ('b', 1, np.int8), 'uint8': ('B', 1, np.uint8), 'int16': ('h', 2, np.int16),
    'uint16': ('H', 2, np.uint16), 'int32': ('i', 4, np.int32), 'uint32': ('I', 4, np.uint32),
    'int64': ('q', 8, np.int64), 'uint64': ('Q', 8, np.uint64), 'float32': ('f', 4, np.float32),
    'float64': ('d', 8, np.float64)}
_U32 = struct.Struct('<I')


class _Cursor:
    __slots__ = ('data', 'off')

    def __init__(self, data):
        self.data = data
        self.off = 4                               # after the encapsulation header

    def align(self, n):
        rem = (self.off - 4) % n
        if rem:
            self.off += n - rem

    def u32(self):
        self.align(4)
        v = _U32.unpack_from(self.data, self.off)[0]
        self.off += 4
        return v


def _string(c):
    n = c.u32()
    s = bytes(c.data[c.off:c.off + max(n - 1, 0)]).decode('utf-8')
    if c.off + n > len(c.data):
        raise ValueError('string runs past the end of the message')
    c.off += n
    return s


def _field_reader(ftype, msgdefs, cache):
    base = ftype.type
    is_array = ftype.is_array
    fixed = ftype.array_size if ftype.is_fixed_size_array() else None
    if ftype.is_primitive_type():
        if base in ('string', 'wstring'):
            if base == 'wstring':
                raise NotImplementedError('wstring')
            if not is_array:
                return _string
            return lambda c: [_string(c) for _ in range(fixed if fixed is not None else c.u32())]
        code, size, dtype = PRIMITIVES[base]
        fmt = struct.Struct('<' + code)
        if not is_array:
            def scalar(c):
                c.align(size)
                v = fmt.unpack_from(c.data, c.off)[0]
                c.off += size
                return v
            return scalar
        dt = np.dtype(dtype).newbyteorder('<')

        def array(c):
            n = fixed if fixed is not None else c.u32()
            if n:
                c.align(size)
            end = c.off + n * size
            if end > len(c.data):
                raise ValueError(f'array of {n} {base} runs past the end of the message')
            v = np.frombuffer(c.data, dtype=dt, count=n, offset=c.off).copy()
            c.off = end
            return v
        return array
    nested = _message_reader(f'{ftype.pkg_name}/{base}', msgdefs, cache)
    if not is_array:
        return nested
    return lambda c: [nested(c) for _ in range(fixed if fixed is not None else c.u32())]


def _message_reader(name, msgdefs, cache):
    if name in cache:
        return cache[name]
    msgdef = msgdefs.get(name)
    if msgdef is None:
        raise ValueError(f'no definition of {name} in the schema')
    readers = []

    def read(c):
        if not readers:                             # empty message: one placeholder byte
            c.off += 1
            return SimpleNamespace()
        return SimpleNamespace(**{fname: r(c) for fname, r in readers})
    cache[name] = read                              # before the fields: recursive types terminate
    readers.extend((f.name, _field_reader(f.type, msgdefs, cache)) for f in msgdef.fields)
    return read


def make_decoder(schema_name: str, schema_text: str):
    """Bytes -> SimpleNamespace (numeric arrays as numpy arrays), or None for unsupported schemas."""
    msgdefs = {}

    def collect(full, short, msgdef):
        msgdefs[full] = msgdefs[short] = msgdef
    try:
        for_each_msgdef(schema_name, schema_text, collect)
        short = f'{schema_name.split("/")[0]}/{schema_name.split("/")[-1]}'
        root = _message_reader(short, msgdefs, {})
    except (NotImplementedError, ValueError, KeyError):
        return None

    def decode(data):
        if len(data) < 4 or data[1] != 1:           # not CDR_LE (0x0001): let mcap_ros2 try
            raise NotImplementedError('only little-endian CDR')
        return root(_Cursor(data))
    return decode
