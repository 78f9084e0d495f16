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


"""The fast frame codec and the frame profiles agree with cantools (the DBC stays the one definition)."""
import can
import cantools
import numpy as np
import pytest

from rubber_rig.rig.can.codec import ByteCodec, crc8
from rubber_rig.rig.can.frames import PROFILES, SampleFrames
from rubber_rig.rig.can.protocol import DBC_PATH, MalformedFrame, Protocol, unwrap

DB = cantools.database.load_file(str(DBC_PATH))
PROTOCOL = Protocol()
SAMPLE_MESSAGES = ('Setpoint', 'SetpointPacked', 'Feedback', 'FeedbackPacked', 'FeedbackApplied', 'FeedbackMeasured')


def _random_values(message, rng):
    values = []
    for s in message.signals[:-1]:
        lo, hi = s.minimum, s.maximum
        v = rng.uniform(lo, hi)
        values.append(int(round(v)) if s.scale == 1 and s.offset == 0 else round(v / s.scale) * s.scale)
    return values


@pytest.mark.parametrize('name', [m.name for m in DB.messages])
def test_byte_codec_encodes_and_decodes_like_cantools(name):
    m = DB.get_message_by_name(name)
    codec = ByteCodec(m)
    rng = np.random.default_rng(3)
    for _ in range(200):
        values = _random_values(m, rng)
        data = codec.encode(values)
        assert codec.check(data) == ''
        ref = m.decode(bytes(data), decode_choices=False)
        expected = m.encode(dict(zip(codec.names + [m.signals[-1].name], values + [0], strict=True)),
                            strict=False)
        assert bytes(data[:-1]) == bytes(expected[:-1])          # same bits as cantools, CRC aside
        assert codec.decode(data) == pytest.approx([ref[n] for n in codec.names], rel=0, abs=1e-9)
        # Protocol packs with the codec: the very bytes, and the very values and types, cantools gives
        msg = PROTOCOL.encode(name, dict(zip(codec.names, values, strict=True)))
        assert bytes(msg.data) == bytes(expected[:-1]) + bytes([crc8(m.frame_id, expected[:-1])])
        _, signals = PROTOCOL.decode(msg)
        assert signals == m.decode(bytes(msg.data), decode_choices=False, scaling=True)
        assert [type(v) for v in signals.values()] == [type(v) for v in m.decode(
            bytes(msg.data), decode_choices=False, scaling=True).values()]


def test_the_byte_codec_takes_every_message_and_its_crc_and_partial_decode_agree():
    """The codec's CRC (affine masks derived from the DBC's lengths and identifiers) equals crc8 byte by byte on
    random payloads, and decoding the first `count` signals gives those of a whole decode.
    """
    taken = []
    for m in DB.messages:
        try:
            codec = ByteCodec(m)
        except ValueError:
            continue
        taken.append(m.name)
        rng = np.random.default_rng(m.frame_id)
        for _ in range(100):
            payload = rng.integers(0, 256, m.length - 1, dtype=np.uint8).tobytes()
            assert codec.crc(int.from_bytes(payload, 'little')) == crc8(m.frame_id, payload)
            data = codec.encode(_random_values(m, rng))
            assert data[-1] == crc8(m.frame_id, data[:-1])
            count = int(rng.integers(0, len(codec.names) + 1))
            assert codec.decode(data, count) == codec.decode(data)[:count]
    assert sorted(taken) == sorted(m.name for m in DB.messages)      # every message of the DBC


def test_byte_codec_saturates_and_refuses_what_it_cannot_represent():
    codec = ByteCodec(DB.get_message_by_name('Setpoint'))
    assert codec.decode(codec.encode([5, 2.0]))[1] == pytest.approx(0.8388607)      # beyond 24 bits: the maximum
    assert codec.decode(codec.encode([5, -2.0]))[1] == pytest.approx(-0.8388608)
    data = codec.encode([5, 1e-3])
    data[2] ^= 1
    assert codec.check(data) == 'Setpoint: CRC mismatch' and codec.check(data[:-1]) == 'Setpoint: 7 bytes instead of 8'
    from cantools.database.can import Message, Signal
    from cantools.database.conversion import BaseConversion
    crc = Signal('X_Crc', 56, 8)
    as_float = BaseConversion.factory(scale=1, offset=0, is_float=True)
    for odd in (Signal('X_Big', 7, 16, byte_order='big_endian'), Signal('X_Float', 0, 32, conversion=as_float)):
        with pytest.raises(ValueError, match=f'X.{odd.name}: not a little-endian integer signal before the CRC'):
            ByteCodec(Message(0x123, 'X', 8, [odd, crc]))


@pytest.mark.parametrize('profile', PROFILES)
def test_every_profile_carries_setpoints_and_samples_both_ways(profile):
    frames = SampleFrames(profile, DB, fs=6000.0)
    first = 4_294_967_290 if profile == 'packed' else 65_530   # across the wrap of the sequence counter
    values = list(np.round(np.linspace(-1e-3, 1e-3, 45) / 1e-7) * 1e-7)
    msgs = frames.encode_setpoints(first, values)
    assert len(msgs) == (3 if profile == 'packed' else 45)
    got = {}
    for m in msgs:
        seq, chunk = frames.decode_setpoints(m)
        seq = unwrap(seq, first, frames.setpoint_modulus)
        got.update({seq + i: v for i, v in enumerate(chunk)})
    assert sorted(got) == list(range(first, first + 45)) and [got[k] for k in sorted(got)] == pytest.approx(values)
    n = frames.feedback_per_frame
    assert n == (6 if profile == 'packed' else 1)
    x, f, u = [1e-4 * (i + 1) for i in range(n)], [10.0 * (i + 1) for i in range(n)], [2e-4] * n
    out = [frames.decode_feedback(m) for m in frames.encode_feedback(first, x, f, u)]
    seq, xs, fs, us = [o for o in out if o is not None][-1] if profile != 'classic' else out[1]
    assert unwrap(seq, first, frames.feedback_modulus) == first
    assert (xs, fs, us) == (pytest.approx(x), pytest.approx(f), pytest.approx(u))


def test_packing_follows_the_rate_and_a_broken_count_is_malformed():
    frames = SampleFrames('packed', DB, fs=1000.0)
    assert [frames.feedback_pack(r) for r in (500, 1000, 2000, 4500, 10000)] == [1, 1, 2, 4, 6]
    assert frames.setpoints_per_frame == 19
    msg = frames.encode_feedback(7, [1e-4, 2e-4], [1.0, 2.0], [0.0, 0.0])[0]
    assert frames.decode_feedback(msg)[0] == 7 and len(frames.decode_feedback(msg)[1]) == 2
    codec = frames.codecs['FeedbackPacked']
    values = codec.decode(msg.data)
    values[1] = 9                                       # more samples than the frame has slots
    bad = can.Message(arbitration_id=msg.arbitration_id, data=codec.encode(values), is_fd=True)
    with pytest.raises(MalformedFrame, match='count 9 outside 1..6'):
        frames.decode_feedback(bad)


def test_classic_pairs_complete_in_either_order_and_a_lost_partner_completes_nothing():
    frames = SampleFrames('classic', DB)
    pairs = [frames.encode_feedback(300 + k, [1e-4 * k], [5.0 * k], [2e-4 * k]) for k in range(4)]
    # priority order on the bus: every FeedbackApplied (0x182) before the FeedbackMeasured (0x183) frames
    out = [frames.decode_feedback(a) for a, _ in pairs] + [frames.decode_feedback(m) for _, m in pairs]
    done = [o for o in out if o is not None]
    assert [d[0] for d in done] == [300, 301, 302, 303]
    assert [d[3][0] for d in done] == pytest.approx([0.0, 2e-4, 4e-4, 6e-4])
    assert frames.decode_feedback(pairs[1][1]) is None                # measured again, applied already used
    lone = frames.encode_feedback(310, [1e-4], [5.0], [1e-4])
    assert frames.decode_feedback(lone[1]) is None                    # its applied frame was lost: no sample
    later = frames.encode_feedback(310 + 256, [2e-4], [6.0], [3e-4])
    assert frames.decode_feedback(later[0])[0] == 310 + 256           # ... the same slot 256 later pairs anew
