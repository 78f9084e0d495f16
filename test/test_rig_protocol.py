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

"""The DBC protocol (cantools both ways), CRC and sequence unwrapping, the driver's frame accounting on a real
python-can virtual bus, and configuration errors that name the field with nothing sent."""
import can
import cantools
import numpy as np
import pytest

from rubber_rig.excitation import Program, ProgramError
from rubber_rig.rig import ConfigError, RigConfig, SimOptions, open_rig
from rubber_rig.rig.can.driver import RigDriver
from rubber_rig.rig.can.protocol import DBC_PATH, MalformedFrame, Protocol, crc8, meet, unwrap
from rubber_rig.safety import LimitError
from rubber_rig.session import run_program


def test_dbc_defines_the_rig_frames_with_units_and_counters():
    db = cantools.database.load_file(str(DBC_PATH))
    names = {m.name for m in db.messages}
    assert names == {'HostCommand', 'HostLimits', 'HostStreamStart', 'Setpoint', 'SetpointPacked', 'Feedback',
                     'FeedbackPacked', 'FeedbackApplied', 'FeedbackMeasured', 'ControllerStatus', 'Temperature',
                     'ControllerHeartbeat', 'HostHeartbeat', 'ControllerIdentity'}
    assert db.version == 'rubber_rig 4'
    ident = db.get_message_by_name('ControllerIdentity')
    assert ident.cycle_time == 1000 and ident.get_signal_by_name('CI_Protocol').length == 8
    assert ident.get_signal_by_name('CI_VelocityMax').unit == 'm/s'
    packed = db.get_message_by_name('FeedbackPacked')
    assert packed.is_fd and packed.length == 64 and packed.get_signal_by_name('FBP_Sequence').length == 32
    assert {s.unit for s in packed.signals if s.name.startswith('FBP_Force')} == {'N'}
    measured = db.get_message_by_name('FeedbackMeasured')
    assert not measured.is_fd and measured.length == 8
    fb = db.get_message_by_name('Feedback')
    units = {s.name: s.unit for s in fb.signals}
    assert units['FB_Displacement'] == 'm' and units['FB_Force'] == 'N' and fb.is_fd and fb.length == 12
    assert db.get_message_by_name('Temperature').get_signal_by_name('TEMP_Specimen').unit == 'degC'
    assert db.get_message_by_name('Setpoint').get_signal_by_name('SP_Sequence').length == 16
    assert db.get_message_by_name('ControllerStatus').get_signal_by_name('ST_Faults').length == 16


def test_dbc_protocol_module_and_rig_status_msg_agree():
    """The DBC is the one definition: protocol's states, fault bits, commands and periods are read from it, and
    msg_defs/msg/RigStatus.msg (which rosidl needs as constants) states the same codes."""
    import re
    from pathlib import Path

    from rubber_rig.rig.can import protocol
    from rubber_rig.rig.sim.controller import SimController
    db = cantools.database.load_file(str(DBC_PATH))
    status = db.get_message_by_name('ControllerStatus')
    states = status.get_signal_by_name('ST_State').choices
    assert {int(k): str(v) for k, v in states.items()} == dict(enumerate(protocol.STATES))
    heartbeat_states = db.get_message_by_name('ControllerHeartbeat').get_signal_by_name('HB_State').choices
    assert {int(k): str(v) for k, v in heartbeat_states.items()} == dict(enumerate(protocol.STATES))
    faults = {int(k): str(v) for k, v in status.get_signal_by_name('ST_Faults').choices.items()}
    assert faults == protocol.FAULT_NAMES and all(bit & (bit - 1) == 0 for bit in faults), 'one bit per fault'
    commands = db.get_message_by_name('HostCommand').get_signal_by_name('CMD_Code').choices
    assert {str(v): int(k) for k, v in commands.items()} == {
        'NOP': protocol.CMD_NOP, 'ENABLE': protocol.CMD_ENABLE, 'ABORT': protocol.CMD_ABORT,
        'RESET': protocol.CMD_RESET, 'DISABLE': protocol.CMD_DISABLE, 'HOLD': protocol.CMD_HOLD,
        'IDENTIFY': protocol.CMD_IDENTIFY}

    msg = (Path(__file__).resolve().parents[1] / 'msg_defs' / 'msg' / 'RigStatus.msg').read_text()
    constants = {m[1]: int(m[2]) for m in re.finditer(r'^uint\d+\s+((?:STATE|FAULT)_\w+)\s*=\s*(\d+)', msg, re.M)}
    assert {k[6:].lower(): v for k, v in constants.items() if k.startswith('STATE_')} == protocol.STATE_CODE
    assert {v: k[6:].lower() for k, v in constants.items() if k.startswith('FAULT_') and v} == protocol.FAULT_NAMES

    fs = 2000.0
    with can.Bus(interface='virtual', channel='dbc_periods', receive_own_messages=False) as bus:
        rig = SimController(bus, fs, SimOptions(), paced=False)
        ticks = (rig.tx._hb_every, rig.tx._st_every, rig.tx._tc_every)
    assert ticks == tuple(round(db.get_message_by_name(n).cycle_time / 1000 * fs)
                          for n in ('ControllerHeartbeat', 'ControllerStatus', 'Temperature')) == (100, 20, 200)
    assert RigConfig().heartbeat_period == db.get_message_by_name('HostHeartbeat').cycle_time / 1000
    with pytest.raises(ValueError, match='Setpoint has no GenMsgCycleTime'):
        protocol.cycle_time('Setpoint')


def test_encode_decode_round_trip_and_resolution():
    p = Protocol()
    msg = p.encode('Feedback', {'FB_Sequence': 65535, 'FB_Displacement': -1.23456789e-3,
                                'FB_Force': 20123.456, 'FB_Setpoint': 0.5e-3})
    assert msg.is_fd and len(msg.data) == 12 and msg.arbitration_id == 0x180
    name, sig = p.decode(msg)
    assert name == 'Feedback' and sig['FB_Sequence'] == 65535
    assert sig['FB_Displacement'] == pytest.approx(-1.23456789e-3, abs=0.5e-7)
    assert sig['FB_Force'] == pytest.approx(20123.456, abs=0.005)
    assert p.decode(can.Message(arbitration_id=0x555, data=b'\0' * 8, is_extended_id=False)) is None


def test_crc_and_length_catch_corruption():
    p = Protocol()
    msg = p.encode('Setpoint', {'SP_Sequence': 7, 'SP_Displacement': 1e-3})
    data = bytearray(msg.data)
    assert data[-1] == crc8(0x100, bytes(data[:-1]))
    for bit in range(8 * 7):
        bad = bytearray(data)
        bad[bit // 8] ^= 1 << (bit % 8)
        with pytest.raises(MalformedFrame, match='CRC'):
            p.decode(can.Message(arbitration_id=0x100, data=bad, is_extended_id=False))
    with pytest.raises(MalformedFrame, match='bytes'):
        p.decode(can.Message(arbitration_id=0x100, data=data[:6], is_extended_id=False))


def test_sequence_unwrap():
    assert unwrap(3, 65534, 1 << 16) == 65539
    assert unwrap(65533, 65538, 1 << 16) == 65533
    assert unwrap(10, 200000, 1 << 16) == 196618          # 3 * 65536 + 10, nearest to the reference
    assert unwrap(5, (1 << 32) - 3, 1 << 32) == (1 << 32) + 5     # the packed frames' 32-bit sequence


def test_meet_counts_late_and_lost_samples_of_a_run():
    assert meet(None, 500, 10) == (0, 0)                # nothing due yet: the run starts the count
    assert meet(100, 100, 10) == (0, 0)                 # in order
    assert meet(100, 103, 10) == (0, 3)                 # 100..102 lost
    assert meet(100, 95, 10) == (5, 0)                  # 95..99 already past, 100..104 used
    assert meet(100, 80, 10) == (10, 0)                 # a duplicate of an old frame: all late
    assert meet(100, 90, 10) == (10, 0)                 # ends just before the due sample


def test_driver_counts_unknown_and_malformed_frames_without_crashing():
    cfg = RigConfig.from_dict({'backend': 'virtual', 'channel': 'rr_test_counts', 'paced': False, 'profile': 'single'})
    host = can.Bus(interface='virtual', channel='rr_test_counts')
    other = can.Bus(interface='virtual', channel='rr_test_counts')
    try:
        drv = RigDriver(host, cfg)
        p = Protocol()
        other.send(can.Message(arbitration_id=0x7FF, data=b'\x01\x02', is_extended_id=False))   # unknown id
        other.send(can.Message(arbitration_id=0x12345, data=b'', is_extended_id=True))          # unknown id
        other.send(can.Message(arbitration_id=0x180, data=b'\0' * 3, is_extended_id=False))     # short
        good = p.encode('Feedback', {'FB_Sequence': 0, 'FB_Displacement': 1e-4, 'FB_Force': 1e3,
                                     'FB_Setpoint': 1e-4})
        bad = bytearray(good.data)
        bad[2] ^= 0x10
        other.send(can.Message(arbitration_id=0x180, data=bad, is_fd=True, is_extended_id=False))  # CRC
        other.send(good)
        other.send(good)                                                                        # duplicate
        other.send(p.encode('Feedback', {'FB_Sequence': 3, 'FB_Displacement': 0.0, 'FB_Force': 0.0,
                                         'FB_Setpoint': 0.0}))                                  # 1, 2 lost
        blocks = [drv.poll(), drv.poll(), drv.poll()]
        st = drv.status
        assert (st.frames_unknown, st.frames_malformed, st.frames_late, st.frames_lost) == (2, 2, 1, 2)
        assert blocks[0].first_sequence == 0 and blocks[0].force[0] == pytest.approx(1e3)
        assert blocks[1].first_sequence == 3 and blocks[1].frames_lost == 2 and blocks[2] is None
    finally:
        host.shutdown()
        other.shutdown()


@pytest.mark.parametrize('cfg, fld', [
    ({'backend': 'nosuchcan'}, 'backend'),
    ({'sample_rate': 0}, 'sample_rate'),
    ({'sample_rate': '1 kHz'}, 'sample_rate'),
    ({'watchdog_timeout': 0.01, 'heartbeat_period': 0.05}, 'heartbeat_period'),
    ({'limits': {'velocity_max': -1}}, 'velocity_max'),
    ({'limits': {'force_limit': 1}}, 'force_limit'),
    ({'sim': {'actuator_frequency': 0}}, 'sim.actuator_frequency'),
    ({'sim': {'faults': [{'type': 'drop', 'frames': ['Setpoints']}]}}, 'sim.faults[0].frames[0]'),
    ({'sim': {'faults': [{'type': 'drop', 'probability': 2}]}}, 'sim.faults[0].probability'),
    ({'sim': {'specimen': {'model': 'linear', 'stiffnes': 1e7}}}, 'sim.specimen.stiffnes'),
    ({'paced': 1}, 'paced'),
])
def test_bad_configuration_names_the_field_and_opens_nothing(cfg, fld):
    before = set(can.interfaces.virtual.channels)
    with pytest.raises(ConfigError) as exc:
        open_rig(cfg)
    assert fld in str(exc.value), str(exc.value)
    assert set(can.interfaces.virtual.channels) == before      # no bus was left open, nothing was sent


def test_bad_program_or_limits_send_nothing():
    before = set(can.interfaces.virtual.channels)
    with pytest.raises(ProgramError, match="block 0 'x': field 'amplitude'"):
        run_program(Program.from_yaml_text('blocks:\n  - {name: x, waveform: sine, frequency: 1 Hz, '
                                           'amplitude: -1 mm, cycles: 1}\n'), {'paced': False})
    prog = Program.from_yaml_text('blocks:\n  - {name: big, waveform: sine, frequency: 1 Hz, amplitude: 8 mm, '
                                  'cycles: 1}\n')
    with pytest.raises(LimitError, match="block 0 'big'.*displacement"):
        run_program(prog, {'paced': False})
    with pytest.raises(ConfigError, match='sample_rate'):
        run_program(prog, {'paced': False, 'sample_rate': -1})
    assert set(can.interfaces.virtual.channels) == before


def test_3khz_short_run_no_loss():
    """3 kHz: near the highest rate the default 1/5 Mbit/s CAN FD bus carries within 70 % load."""
    prog = Program.from_yaml_text('blocks:\n  - {waveform: sine, frequency: 20 Hz, amplitude: 0.5 mm, '
                                  'cycles: 5}\n')
    r = run_program(prog, {'paced': False, 'sample_rate': 3000.0})
    assert r.completed and r.final_status.frames_lost == 0
    assert r.sequence.size >= prog.n_samples(3000.0)
    assert np.all(np.diff(r.sequence) == 1)


def test_a_rate_the_configured_bus_cannot_carry_is_refused_before_the_bus_opens():
    before = set(can.interfaces.virtual.channels)
    prog = Program.from_yaml_text('blocks:\n  - {waveform: sine, frequency: 20 Hz, amplitude: 0.5 mm, cycles: 2}\n')
    with pytest.raises(ConfigError, match=r"'sample_rate': 5000 Hz needs 10[0-9] % of the 1/5 Mbit/s CAN FD bus "
                                          r'with single frames, more than max_bus_load \(70 %\): this bus carries at '
                                          r'most 34[0-9]{2} Hz'):
        run_program(prog, {'paced': False, 'sample_rate': 5000.0, 'profile': 'single'})
    with pytest.raises(ConfigError, match='needs .* than max_bus_load \\(100 %\\)'):
        run_program(prog, {'paced': False, 'sample_rate': 5000.0, 'max_bus_load': 1.0, 'profile': 'single'})
    with pytest.raises(ConfigError, match=r"'sample_rate': 1000 Hz needs 8[0-9] % of the 0.5 Mbit/s classic CAN bus "
                                          r'with classic frames.*at most 85[0-9] Hz'):
        run_program(prog, {'paced': False, 'bitrate': 500_000, 'fd': False})
    with pytest.raises(ConfigError, match=r"'sample_rate': 20000 Hz needs 7[0-9] % of the 1/5 Mbit/s CAN FD bus "
                                          r'with packed frames'):
        run_program(prog, {'paced': False, 'sample_rate': 20000.0})
    with pytest.raises(ConfigError, match=r"field 'profile': .*Packed is a CAN FD frame"):
        run_program(prog, {'paced': False, 'fd': False, 'profile': 'packed'})
    assert set(can.interfaces.virtual.channels) == before          # no bus was opened
    cfg = RigConfig.from_dict({'sample_rate': 2000.0})
    assert cfg.bus_load().load == pytest.approx(2000 * cfg.bus_load().per_sample + cfg.bus_load().periodic)
    with open_rig({'paced': False, 'sample_rate': 2000.0}) as rig:
        assert rig.driver.status.extra['bus_load'] == pytest.approx(cfg.bus_load().load)
