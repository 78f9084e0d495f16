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
"""CAN frame durations and the protocol's bus load (rubber_rig.rig.can.timing) against hand-counted frames."""
import pytest

from rubber_rig.rig.can.timing import fd_length, frame_bits, frame_time, protocol_load


def test_classic_frame_bits_match_the_iso_frame_layout():
    # 8 data bytes: 44 + 64 + 3 = 111 bits without stuffing; the stuffed part (98 bits) can grow by 24
    assert frame_bits(8, worst_case=False) == (111, 0)
    assert frame_bits(8) == (135, 0)
    assert frame_bits(0, worst_case=False) == (47, 0)
    assert frame_bits(8, worst_case=False, extended=True) == (131, 0)     # CAN 2.0B: 67 + 8 n
    assert frame_time(8, 1e6) == pytest.approx(135e-6) and frame_time(8, 5e5) == pytest.approx(270e-6)
    with pytest.raises(ValueError, match='0-8 bytes'):
        frame_bits(12)


def test_fd_frames_switch_to_the_data_bitrate_after_arbitration():
    nominal, data = frame_bits(12, fd=True, worst_case=False)
    assert nominal == 17 + 13                        # arbitration + tail at the nominal rate
    assert data == 1 + 4 + 96 + 5 + 17 + 5           # ESI, DLC, data, stuff count, CRC-17 with fixed stuff bits
    assert frame_time(12, 1e6, 5e6, fd=True, worst_case=False) == pytest.approx(30e-6 + 128 / 5e6)
    # the estimate for the Feedback frame: about 0.055-0.06 ms; worst-case stuffing adds the rest
    assert 55e-6 < frame_time(12, 1e6, 5e6, fd=True, worst_case=False) < 60e-6 < frame_time(12, 1e6, 5e6, fd=True)
    assert frame_bits(20, fd=True, worst_case=False)[1] == 1 + 4 + 160 + 5 + 21 + 6   # CRC-21 above 16 bytes
    # without bit-rate switch everything runs at the nominal rate
    assert frame_bits(12, fd=True, bitrate_switch=False) == (sum(frame_bits(12, fd=True)), 0)
    assert [fd_length(n) for n in (8, 9, 13, 33, 64)] == [8, 12, 16, 48, 64]
    with pytest.raises(ValueError, match='64 bytes'):
        fd_length(65)


def test_single_sample_frames_fill_a_1_5_mbit_bus_at_about_5_khz():
    load = protocol_load(1000.0, 1e6, 5e6, fd=True, profile='single')
    setpoint, feedback = load.frames['Setpoint'][1], load.frames['Feedback'][1]
    assert setpoint == pytest.approx(135e-6) and feedback == pytest.approx(frame_time(12, 1e6, 5e6, fd=True))
    assert load.per_sample == pytest.approx(setpoint + feedback)
    # periodic frames: status 100/s, temperature 10/s, two heartbeats 20/s each and the identity 1/s, all 8-byte
    # classic
    assert load.periodic == pytest.approx(151 * 135e-6)
    assert load.load == pytest.approx(1000 * load.per_sample + load.periodic)
    assert 4800 < load.max_rate < 5000 and 2300 < load.rate_at(0.5) < 2500
    assert protocol_load(load.max_rate, 1e6, 5e6, profile='single').load == pytest.approx(1.0)


def test_packed_frames_carry_10_khz_within_half_a_1_5_mbit_bus():
    load = protocol_load(10000.0, 1e6, 5e6, fd=True)           # packed is the FD default
    sp, fb = load.frames['SetpointPacked'], load.frames['FeedbackPacked']
    t64 = frame_time(64, 1e6, 5e6, fd=True)
    assert sp == pytest.approx((10000 / 19, t64)) and fb == pytest.approx((10000 / 6, t64))
    assert set(load.frames) == {'SetpointPacked', 'FeedbackPacked', 'ControllerStatus', 'Temperature',
                                'ControllerHeartbeat', 'HostHeartbeat', 'ControllerIdentity'}
    assert load.load == pytest.approx(10000 * t64 * (1 / 19 + 1 / 6) + 151 * 135e-6) and load.load < 0.5
    # packing follows the rate (at most 1 ms of samples per frame): at 1 kHz one sample per 64-byte frame
    one = protocol_load(1000.0, 1e6, 5e6)
    assert one.frames['FeedbackPacked'] == pytest.approx((1000, t64))
    assert protocol_load(one.rate_at(0.5), 1e6, 5e6).load <= 0.5 + 1e-9
    assert 12000 < one.rate_at(0.5) < 14000 and protocol_load(one.max_rate, 1e6, 5e6).load == pytest.approx(1.0)


def test_the_classic_profile_runs_on_8_byte_frames_and_says_its_limit():
    load = protocol_load(500.0, 500e3, fd=False)             # classic is the default without FD
    assert {n: f[1] for n, f in load.frames.items() if n.startswith(('Setpoint', 'Feedback'))} == pytest.approx(
        {'Setpoint': frame_time(8, 500e3), 'FeedbackApplied': frame_time(6, 500e3),
         'FeedbackMeasured': frame_time(8, 500e3)})
    assert 590 < load.rate_at(0.5) < 600 and 1240 < load.max_rate < 1250
    assert 1240 < protocol_load(500.0, 1e6, fd=False).rate_at(0.5) < 1250


def test_a_classic_bus_cannot_carry_fd_frames():
    with pytest.raises(ValueError, match='Feedback is a CAN FD frame.*classic CAN bus cannot carry the single'):
        protocol_load(1000.0, 1e6, fd=False, profile='single')
    with pytest.raises(ValueError, match='Packed is a CAN FD frame.*cannot carry the packed'):
        protocol_load(1000.0, 1e6, fd=False, profile='packed')
