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

"""Message signatures: a canonical encoding, a signer with a monotonic counter, a verifier with a replay window.

As MAVLink 2 signs a packet (link id, 48-bit timestamp, truncated SHA-256 over key + packet), a rubber_rig
message carries (link, counter, tag): ``tag = HMAC-SHA256(key, canonical(purpose, link, counter, fields))``
with the rig's secret key (keys.py). The fields are every content field of the message in a fixed order (the
stream id and sequence of a setpoint batch among them); `purpose` says what the message is for
('setpoint_stream', 'samples', 'open_stream', ...), so a message copied from one channel onto another does not
verify. The counter is microseconds since the Unix epoch, strictly increasing per signer: a receiver accepts a
counter only above the last it accepted from that link for that purpose (a replayed or copied message is
refused), and the first message of a link only if its counter is within `window` seconds of the receiver's
clock (a message recorded an hour ago does not open a new link). Time is an input: both take `clock`.

What this does not do: hide anything (everything on the domain stays readable), or stop a process that holds
the key. Refusals are counted by purpose and by the channel they came on (the sender's topic, which a forger
cannot hide), and the latest is kept with its reason, for /diagnostics.
"""
from __future__ import annotations

import array
import hashlib
import hmac
import math
import struct
import sys
import threading
import time
from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

VERSION = b'rubber_rig signature v1\x00'
TAG_BYTES = 32
WINDOW = 10.0       # [s] how far the first counter of a link may be from the receiver's clock
MAX_CHANNELS = 64   # (purpose, channel) refusal counters kept apart; more are counted under 'other channels'


def _text(value: str) -> bytes:
    raw = value.encode('utf-8')
    return struct.pack('<I', len(raw)) + raw


def _value(value) -> bytes:
    """One field value, type-tagged and length-prefixed (no two different values encode alike)."""
    if type(value) is array.array and value.typecode == 'd' and sys.byteorder == 'little':
        return b'F' + struct.pack('<I', len(value)) + value.tobytes()     # rclpy's float64[]: no copy through numpy
    if isinstance(value, (bool, np.bool_)):
        return b'b' + (b'\x01' if value else b'\x00')
    if isinstance(value, (int, np.integer)):
        return b'i' + int(value).to_bytes(16, 'little', signed=True)
    if isinstance(value, (float, np.floating)):
        return b'f' + struct.pack('<d', float(value))
    if isinstance(value, str):
        return b's' + _text(value)
    if isinstance(value, (bytes, bytearray, memoryview)):
        raw = bytes(value)
        return b'y' + struct.pack('<I', len(raw)) + raw
    if isinstance(value, (list, tuple)) and any(isinstance(v, str) for v in value):
        return b'S' + struct.pack('<I', len(value)) + b''.join(_text(str(v)) for v in value)
    values = np.asarray(value)
    kind = {'f': ('F', '<f8'), 'u': ('U', '<u8'), 'i': ('I', '<i8'), 'b': ('B', '|u1')}.get(values.dtype.kind)
    if kind is None or values.ndim != 1:
        raise TypeError(f'cannot sign a value of type {type(value).__name__} ({values.dtype}, {values.ndim}-d)')
    return kind[0].encode() + struct.pack('<I', values.size) + np.ascontiguousarray(values, kind[1]).tobytes()


def canonical(purpose: str, link: str, counter: int, fields: Iterable[tuple[str, object]]) -> bytes:
    """The bytes a signature covers: version, purpose, link, counter and each (name, value) of `fields` in order.

    Values: bool, int (|v| < 2**127), float (IEEE 754 binary64), str (UTF-8), bytes, and 1-d sequences of numbers
    (encoded as little-endian float64, int64 or uint64 by their kind) or of strings.
    """
    fields = list(fields)
    parts = [VERSION, _text(purpose), _text(link), struct.pack('<Q', int(counter)), struct.pack('<I', len(fields))]
    for name, value in fields:
        parts += [_text(name), _value(value)]
    return b''.join(parts)


def _tag(key: bytes, purpose: str, link: str, counter: int, fields) -> bytes:
    return hmac.new(key, canonical(purpose, link, counter, fields), hashlib.sha256).digest()


class Signer:
    """Signs messages of one sender (`link`: its fully qualified node name) with `key` (keys.load_key).

    The counter is ``clock()`` in microseconds, and at least one above the previous one (a clock that stands
    still or steps back does not make a replayable signature). Thread-safe.
    """

    def __init__(self, key: bytes, link: str, clock: Callable[[], float] = time.time):
        self.key, self.link, self._clock = bytes(key), str(link), clock
        self._last, self._lock = 0, threading.Lock()

    def next_counter(self) -> int:
        with self._lock:
            self._last = max(self._last + 1, int(self._clock() * 1e6))
            return self._last

    def sign(self, purpose: str, fields) -> tuple[str, int, bytes]:
        """(link, counter, tag) for a message of `purpose` with content `fields` ((name, value) pairs)."""
        counter = self.next_counter()
        return self.link, counter, _tag(self.key, purpose, self.link, counter, fields)


@dataclass(frozen=True)
class Refusal:
    """One refused message: what it claimed to be (purpose, link), where it came from (the channel: the sender's
    topic or service), and why it was refused.
    """

    purpose: str
    where: str
    link: str
    why: str

    def describe(self) -> str:
        return f'{self.purpose} on {self.where} (signer {self.link or "none"}) refused: {self.why}'


class Verifier:
    """Checks signatures made with `key` and keeps the replay state of every link it accepted from.

    key None: no key configured. Then, and whenever `required` is False, an unsigned message is accepted (and
    counted as such); a signed one is still checked when there is a key. `window` [s]: how far from ``clock()``
    the first counter of a link may be. Refusals are counted per (purpose, channel) in ``refused``.
    """

    def __init__(self, key: bytes | None, required: bool = True, clock: Callable[[], float] = time.time,
                 window: float = WINDOW):
        self.key, self.required, self._clock, self.window = key, bool(required), clock, float(window)
        self._last: dict[tuple[str, str], int] = {}
        self.accepted = 0
        self.unsigned_accepted = 0
        self.refused: dict[tuple[str, str], int] = {}
        self.last_refusal: Refusal | None = None
        self._said: dict[tuple[str, str], float] = {}   # (purpose, channel) -> clock() of its latest log line
        self._lock = threading.Lock()

    def check(self, purpose: str, link: str, counter: int, tag: bytes, fields) -> str:
        """'' if the message may be used, else why not; nothing is counted (verify() counts)."""
        if not tag:
            if self.key is None or not self.required:
                return ''
            return 'unsigned (every command and sample batch of this rig must carry the rig key\'s signature)'
        if self.key is None:
            return ''     # development mode without a key: signatures cannot be checked
        if len(tag) != TAG_BYTES or not hmac.compare_digest(bytes(tag), _tag(self.key, purpose, link, counter, fields)):
            return 'bad signature (forged, altered, copied from another purpose, or signed with another key)'
        last = self._last.get((purpose, link))
        if last is not None and counter <= last:
            return f'replayed: counter {counter} is not above {last}, the last accepted from {link}'
        age = self._clock() - counter * 1e-6
        if last is None and abs(age) > self.window:
            return (f'stale: the first message of {link} was signed {age:.1f} s from now (more than {self.window:g} s: '
                    'a replay of an old message?)')
        return ''

    def verify(self, purpose: str, where: str, link: str, counter: int, tag: bytes, fields) -> str:
        """Check a message of `purpose` that came on channel `where`; '' if accepted, else why it was refused (the
        refusal is counted and kept as ``last_refusal``).
        """
        tag = bytes(tag)
        with self._lock:
            why = self.check(purpose, link, counter, tag, fields)
            if why:
                key = (purpose, where)
                if key not in self.refused and len(self.refused) >= MAX_CHANNELS:
                    key = (purpose, 'other channels')
                self.refused[key] = self.refused.get(key, 0) + 1
                self.last_refusal = Refusal(purpose, where, link, why)
                return why
            if tag and self.key is not None:
                self._last[(purpose, link)] = int(counter)
            else:
                self.unsigned_accepted += 1
            self.accepted += 1
            return ''

    def due_to_say(self, purpose: str, where: str, every: float = 1.0) -> bool:
        """Whether a refusal on (purpose, channel) is to be logged now: at most once per `every` seconds per channel,
        so that a flood on one channel does not hide the refusals on another.
        """
        now, key = self._clock(), (purpose, where)
        if now - self._said.get(key, -math.inf) < every:
            return False
        if len(self._said) >= MAX_CHANNELS and key not in self._said:
            self._said.clear()
        self._said[key] = now
        return True

    @property
    def refused_total(self) -> int:
        return sum(self.refused.values())

    def lines(self) -> dict[str, str]:
        """The /diagnostics values: refusals in total, per purpose and channel, the latest with its reason."""
        out = {'auth': ('required' if self.required else 'optional (development)') if self.key is not None
               else ('no key: refusing unsigned commands' if self.required else 'OFF (no key, auth.required false)'),
               'auth_refused': str(self.refused_total)}
        if self.unsigned_accepted:
            out['auth_unsigned_accepted'] = str(self.unsigned_accepted)
        if self.refused:
            out['auth_refused_by_channel'] = ', '.join(f'{p} on {w}: {n}' for (p, w), n in sorted(self.refused.items()))
        if self.last_refusal is not None:
            out['auth_last_refusal'] = self.last_refusal.describe()
        return out
