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

"""Raw CAN logs (RigConfig.can_log, rubber_rig.rig.can.canlog, `rubber-rig canlog`): a program on the simulated
rig is logged as BLF, ASC and candump .log; the decoded log gives the same samples, sequences and counts as the
driver, plain python-can reads the files, and bad names, bad places and damaged logs are refused or reported; a
damaged line of a text log (.asc, .log) is skipped and counted, and every frame before and after it is kept."""
import datetime
import importlib
import json
import os
import re
import subprocess
import sys
import time
import warnings
from pathlib import Path

import can
import numpy as np
import pytest

from rubber_rig.cli.main import main as cli_main
from rubber_rig.excitation import Program
from rubber_rig.recording import Recorder
from rubber_rig.rig import ConfigError, RigConfig, open_rig
from rubber_rig.rig import interface as rig_interface
from rubber_rig.rig.can.canlog import CanLogError, CanLogWarning
from rubber_rig.rig.can.canlog_reader import decode_log
from rubber_rig.rig.can.canlog_text import MAX_SKIPPED_REPORTED, TextLogReader
from rubber_rig.rig.can.canlog_time import TimeCheck
from rubber_rig.session import run_program
from rubber_rig.settings import settings_of

FAST = {'paced': False, 'profile': 'single'}   # one frame per sample: frame counts are sample counts
FORMATS = ('.blf', '.asc', '.log')
PROG = Program.from_yaml_text('name: canlog\nblocks:\n  - {waveform: sine, frequency: 8 Hz, amplitude: 0.5 mm, '
                              'cycles: 4}\n')
RUBBER_RIG = Path(sys.executable).with_name('rubber-rig')
FEEDBACK, SETPOINT = 0x180, 0x100


def read_plain(path):
    """The frames of a log through python-can alone (ASC: times relative to its start)."""
    return list(can.LogReader(str(path)))


def decode_clean(path):
    with warnings.catch_warnings():
        warnings.simplefilter('error', CanLogWarning)   # a complete log decodes without a warning
        return decode_log(path)


@pytest.fixture(scope='module')
def logged_runs(tmp_path_factory):
    """One fast run per format: {suffix: (RunResult, log path, wall time before, wall time after)}."""
    out = {}
    for suffix in FORMATS:
        path = tmp_path_factory.mktemp('canlog') / f'rig{suffix}'
        t0 = time.time()
        r = run_program(PROG, dict(FAST, can_log=str(path)))
        out[suffix] = (r, path, t0, time.time())
    return out


# ---- the log of a run decodes to the run -------------------------------------------------------------------

@pytest.mark.parametrize('suffix', FORMATS)
def test_decoded_log_equals_the_run(logged_runs, suffix):
    r, path, _, _ = logged_runs[suffix]
    assert r.completed, r.message
    log = decode_clean(path)
    assert log.complete and not log.warnings and log.format == suffix
    # the samples the driver assembled, frame by frame (DBC resolution: 0.1 um, 0.01 N)
    np.testing.assert_array_equal(log.sequence, r.sequence)
    np.testing.assert_allclose(log.displacement, r.displacement, rtol=0, atol=0.5e-7)
    np.testing.assert_allclose(log.force, r.force, rtol=0, atol=0.005)
    np.testing.assert_allclose(log.setpoint, r.setpoint, rtol=0, atol=0.5e-7)
    assert np.all(np.abs(log.temperature[np.isfinite(log.temperature)] - 20.0) < 0.2)
    np.testing.assert_array_equal(log.status, 0)
    # the host's setpoints: the program, from sequence 0
    n = PROG.n_samples(1000.0)
    np.testing.assert_array_equal(log.setpoint_sequence, np.arange(log.setpoint_sequence.size))
    np.testing.assert_allclose(log.setpoint_displacement[:n], PROG.setpoints(1000.0), rtol=0, atol=0.6e-7)
    # frame counts agree with what the driver counted
    st = r.final_status
    assert log.frames['Feedback'] == st.samples_received + st.frames_late
    assert log.frames['Setpoint'] == st.setpoints_sent
    assert log.frames['ControllerHeartbeat'] == st.extra['heartbeats_received']
    assert log.frames_malformed == st.frames_malformed == 0 and log.frames_unknown == 0
    assert log.gaps == [] and log.samples_lost == st.frames_lost == 0
    assert sum(log.frames.values()) == log.frames_total == log.frames_rx + log.frames_tx
    assert [s for _, s in log.states][:2] == ['idle', 'running'] and log.faults_seen == []
    assert log.commands[-1][1] == 'ABORT'          # closing the rig commands the ramp to rest


@pytest.mark.parametrize('profile, rate', [('packed', 6000.0), ('classic', 500.0)])
def test_packed_and_classic_logs_decode_to_the_run(tmp_path, profile, rate):
    """Packed frames (6 samples per frame at 6 kHz) and the classic pairs decode to the same samples."""
    path = tmp_path / 'rig.blf'
    cfg = {'paced': False, 'profile': profile, 'sample_rate': rate, 'can_log': str(path)}
    if profile == 'classic':
        cfg['fd'] = False
    r = run_program(PROG, cfg)
    assert r.completed, r.message
    log = decode_clean(path)
    np.testing.assert_array_equal(log.sequence, r.sequence)
    np.testing.assert_allclose(log.force, r.force, rtol=0, atol=0.005)
    np.testing.assert_allclose(log.setpoint, r.setpoint, rtol=0, atol=0.5e-7)
    np.testing.assert_allclose(log.setpoint_displacement[:PROG.n_samples(rate)], PROG.setpoints(rate), rtol=0,
                               atol=0.6e-7)
    assert log.samples_lost == 0 and log.gaps == [] and np.all(np.diff(log.time) >= 0)
    st = r.final_status
    if profile == 'packed':
        assert log.frames['FeedbackPacked'] == pytest.approx(st.samples_received / 6, abs=20)
        assert log.frames['SetpointPacked'] == pytest.approx(st.setpoints_sent / 19, abs=20)
    else:
        assert log.frames['FeedbackApplied'] == log.frames['FeedbackMeasured'] == st.samples_received
    assert 'Feedback' not in log.frames and 'Setpoint' not in log.frames or profile == 'classic'


@pytest.mark.parametrize('suffix', FORMATS)
def test_plain_python_can_reads_the_log(logged_runs, suffix):
    """Direction, CAN FD flags, one channel and wall-clock timestamps in order, as any CAN tool expects."""
    r, path, t0, t1 = logged_runs[suffix]
    frames = read_plain(path)
    assert len(frames) == decode_clean(path).frames_total
    fb = [m for m in frames if m.arbitration_id == FEEDBACK]
    sp = [m for m in frames if m.arbitration_id == SETPOINT]
    assert len(fb) == r.sequence.size and len(sp) == r.final_status.setpoints_sent
    assert all(m.is_rx and m.is_fd and m.bitrate_switch and len(m.data) == 12 for m in fb)
    assert all(not m.is_rx and not m.is_fd and len(m.data) == 8 for m in sp)
    stamps = np.array([m.timestamp for m in frames])
    assert np.all(np.diff(stamps) >= 0)
    log = decode_clean(path)
    np.testing.assert_allclose(log.time, stamps[[m.arbitration_id == FEEDBACK for m in frames]] - stamps[0],
                               rtol=0, atol=2e-6)
    slack = 0.0011 if suffix == '.asc' else 1e-5     # ASC keeps its start time to the millisecond
    assert t0 - slack <= log.start and log.end <= t1 + slack
    if suffix != '.asc':
        assert (stamps[0], stamps[-1]) == (log.start, log.end)
    assert len({m.channel for m in frames}) == 1
    assert frames[0].channel == ('sim0' if suffix == '.log' else 0)


@pytest.mark.parametrize('millisecond', [4, 40, 400])
def test_asc_start_time_is_read_to_the_millisecond(tmp_path, millisecond):
    """python-can's ASCWriter writes the start's milliseconds without leading zeros ('.40' for 40 ms); decode_log
    reads them as milliseconds, as CANoe's three digits are."""
    t = datetime.datetime(2026, 3, 2, 9, 15, 30, millisecond * 1000 + 600).timestamp()
    path = tmp_path / 'ms.asc'
    with can.ASCWriter(str(path)) as w:
        w.on_message_received(can.Message(timestamp=t, arbitration_id=0x123, data=b'\x01', is_extended_id=False))
        w.on_message_received(can.Message(timestamp=t + 0.25, arbitration_id=0x123, data=b'\x02',
                                          is_extended_id=False))
    log = decode_clean(path)
    assert log.frames == {'0x123': 2} and log.frames_unknown == 2
    assert log.start == pytest.approx(t, abs=1e-3) and log.duration == pytest.approx(0.25, abs=1e-6)


def test_paced_run_keeps_the_bus_timestamps(tmp_path):
    """Paced, the controller's feedback frames come in real time and the log says so, in order, although the
    driver reads them in bursts after it has sent newer frames."""
    prog = Program.from_yaml_text('name: paced\nblocks:\n  - {waveform: sine, frequency: 5 Hz, amplitude: 0.3 mm, '
                                  'cycles: 2}\n')
    path = tmp_path / 'paced.log'
    # the test is about the log's timestamps; the watchdog (0.1 s by default, tested elsewhere) gets room for a
    # busy CI host stalling this process, as the other paced runs in the tests do
    r = run_program(prog, {'paced': True, 'can_log': str(path), 'watchdog_timeout': 1.0})
    assert r.completed, r.message
    log = decode_clean(path)
    np.testing.assert_array_equal(log.sequence, r.sequence)
    # real time: the feedback frames span the samples' duration (single ticks may come in bursts on a busy host)
    assert np.all(np.diff(log.time) >= 0)
    assert log.time[-1] - log.time[0] == pytest.approx((r.sequence[-1] - r.sequence[0]) * 1e-3, rel=0.15)
    stamps = np.array([m.timestamp for m in read_plain(path)])
    assert np.all(np.diff(stamps) >= 0)
    assert 0.0 <= log.bus_load() < 0.5     # a real-time 1 kHz stream: a realistic load on a 1/5 Mbit/s bus


def test_bad_frames_and_loss_decode_as_the_driver_counted(tmp_path):
    faults = [{'type': 'drop', 'probability': 0.005, 'frames': ['Feedback']},
              {'type': 'corrupt', 'probability': 0.002, 'frames': ['Feedback', 'Temperature']},
              {'type': 'duplicate', 'probability': 0.003}]
    path = tmp_path / 'bad.blf'
    r = run_program(PROG, dict(FAST, sim={'faults': faults}, can_log=str(path)))
    st = r.final_status
    assert r.completed, r.message
    assert st.frames_lost > 0 and st.frames_malformed > 0 and st.frames_late > 0
    log = decode_clean(path)
    np.testing.assert_array_equal(log.sequence, r.sequence)
    np.testing.assert_allclose(log.force, r.force, rtol=0, atol=0.005)
    assert (log.samples_lost, log.frames_malformed, log.frames_late) == (st.frames_lost, st.frames_malformed,
                                                                         st.frames_late)
    assert len(log.gaps) == np.count_nonzero(np.diff(r.sequence) > 1)


def test_fault_and_abort_path_closes_a_complete_log(tmp_path):
    """A fault stops the program with the controller's ramp; the log is complete and shows the ramp."""
    path = tmp_path / 'abort.asc'
    r = run_program(PROG, dict(FAST, limits={'force_max': 3e3}, can_log=str(path)))
    assert not r.completed and 'force' in r.message
    log = decode_clean(path)
    assert log.complete
    aborts = [t for t, c, _ in log.commands if c == 'ABORT']
    ramp = [t for t, s in log.states if s == 'ramping_down']
    assert aborts and ramp and aborts[0] <= ramp[0]
    np.testing.assert_array_equal(log.sequence, r.sequence)
    np.testing.assert_allclose(log.setpoint, r.setpoint, rtol=0, atol=0.5e-7)


def test_open_rig_reports_the_log_and_closes_it(tmp_path):
    path = tmp_path / 'open.log'
    with open_rig(dict(FAST, can_log=str(path))) as rig:
        assert rig.can_log is not None and rig.wait_ready(5.0)
        assert any('raw CAN log' in text and str(path) in text for _, text in rig.driver.events)
    assert rig.can_log.closed and rig.can_log.write_errors == 0
    assert rig.can_log.frames_written == rig.can_log.frames_tx + rig.can_log.frames_rx > 0
    log = decode_clean(path)
    assert log.frames['HostLimits'] == 1 and log.frames['HostHeartbeat'] >= 1


# ---- the parameter ------------------------------------------------------------------------------------------

def test_can_log_is_a_described_setting():
    s = {x.name: x for x in settings_of(RigConfig)}['can_log']
    assert s.default == '' and '.blf' in s.doc and '.asc' in s.doc and '.log' in s.doc
    assert RigConfig().can_log == ''


def rig_driver_module():
    pytest.importorskip('rclpy')
    for name in ('rubber_rig.nodes.rig_driver_node', 'rubber_rig.nodes.rig_driver'):
        try:
            return importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
    pytest.skip('no rig_driver node module')


@pytest.fixture
def ros_context():
    rclpy = pytest.importorskip('rclpy')
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def test_rig_driver_declares_can_log():
    """The node declares every RigConfig setting as a parameter, so can_log:=... reaches the core."""
    rig_driver = rig_driver_module()
    assert 'can_log' in {s.name for s in rig_driver.RIG_SETTINGS}
    assert 'can_log' not in rig_driver.LIVE_PARAMETERS     # the log is opened at configure


@pytest.mark.ros
def test_rig_driver_node_writes_the_log_and_refuses_bad_ones(ros_context, tmp_path):
    from rclpy.parameter import Parameter

    from rubber_rig.nodes.params import ParameterError
    node_class = rig_driver_module().RigDriverNode
    path = tmp_path / 'node.blf'
    node = node_class(context=ros_context, parameter_overrides=[Parameter('can_log', value=str(path))])
    try:
        assert node.lifecycle_state == 'active' and node.rig.can_log is not None
        assert node.rig.wait_ready(5.0)
    finally:
        node.close()
        node.destroy_node()
    log = decode_clean(path)
    assert log.frames['HostLimits'] == 1 and log.frames['ControllerHeartbeat'] >= 1
    # a bad suffix is a bad parameter at start; an unwritable place fails configure, with the reason
    with pytest.raises(ParameterError, match="'can_log'.*supported: .blf"):
        node_class(context=ros_context, parameter_overrides=[Parameter('can_log', value=str(tmp_path / 'x.trc'))])
    node = node_class(context=ros_context, parameter_overrides=[
        Parameter('can_log', value=str(tmp_path / 'missing' / 'x.log'))])
    try:
        assert node.lifecycle_state == 'unconfigured' and node.rig is None
    finally:
        node.destroy_node()


@pytest.fixture
def no_bus(monkeypatch):
    """Fail the test if open_rig opens a bus."""
    opened = []
    monkeypatch.setattr(rig_interface, 'open_bus', lambda *a, **k: opened.append(a) or pytest.fail('bus opened'))
    return opened


@pytest.mark.parametrize('name', ['rig.trc', 'rig.csv', 'rig', 'rig.blf.gz'])
def test_unknown_suffix_is_refused_before_the_rig_opens(tmp_path, no_bus, name):
    path = tmp_path / name
    with pytest.raises(ConfigError) as exc:
        open_rig(dict(FAST, can_log=str(path)))
    assert exc.value.field == 'can_log'
    for suffix in FORMATS:
        assert suffix in str(exc.value)
    assert not path.exists() and not no_bus
    with pytest.raises(ConfigError, match='can_log'):
        run_program(PROG, dict(FAST, can_log=str(path)))
    assert not no_bus


def test_unwritable_place_is_refused_before_the_rig_opens(tmp_path, no_bus):
    a_file = tmp_path / 'file.txt'
    a_file.write_text('x')
    cases = {tmp_path / 'missing' / 'rig.blf': 'does not exist', a_file / 'rig.blf': 'not a directory',
             tmp_path / 'dir.log': 'is a directory'}
    (tmp_path / 'dir.log').mkdir()
    if os.geteuid() != 0:    # root writes anywhere: the permission case needs an ordinary user
        locked = tmp_path / 'locked'
        locked.mkdir(mode=0o500)
        cases[locked / 'rig.asc'] = 'not writable'
    for path, why in cases.items():
        with pytest.raises(ConfigError) as exc:
            open_rig(dict(FAST, can_log=str(path)))
        assert exc.value.field == 'can_log' and why in str(exc.value) and str(path) in str(exc.value)
    assert not no_bus


def test_a_failing_disk_does_not_stop_the_rig(tmp_path):
    """Writes to a full disk (/dev/full) fail: the run completes, the error is counted and reported once."""
    if not os.path.exists('/dev/full'):
        pytest.skip('no /dev/full on this system')
    path = tmp_path / 'full.log'
    path.symlink_to('/dev/full')
    rig = open_rig(dict(FAST, can_log=str(path)))
    try:
        r = run_program(PROG, FAST, rig=rig)
        assert r.completed, r.message
    finally:
        rig.close()
    tap = rig.can_log
    assert tap.write_errors >= 1 and str(path) in tap.error and 'No space left' in tap.error
    reported = [text for level, text in rig.driver.events if level == 'warn' and 'raw CAN log' in text]
    assert reported == [tap.error]


# ---- damaged logs ------------------------------------------------------------------------------------------

@pytest.mark.parametrize('suffix', FORMATS)
def test_truncated_log_decodes_what_is_there_with_a_warning(logged_runs, tmp_path, suffix):
    r, path, _, _ = logged_runs[suffix]
    data = path.read_bytes()
    cut = tmp_path / f'cut{suffix}'
    end = int(len(data) * 0.6)
    if data[end - 1:end] == b'\n':
        end -= 1     # cut inside a line: a cut at a line end leaves a text log that is complete as far as it goes
    cut.write_bytes(data[:end])
    with pytest.warns(CanLogWarning, match='truncated|not closed'):
        log = decode_log(cut)
    assert not log.complete and log.warnings
    k = len(log)
    assert 0.2 * r.sequence.size < k < r.sequence.size
    np.testing.assert_array_equal(log.sequence, r.sequence[:k])
    np.testing.assert_allclose(log.displacement, r.displacement[:k], rtol=0, atol=0.5e-7)


def test_corrupt_blf_decodes_up_to_the_damage_with_a_warning(logged_runs, tmp_path):
    """BLF is binary: it is read up to the first object python-can cannot read."""
    r, path, _, _ = logged_runs['.blf']
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid:mid + 32] = b'\xa5' * 32                  # inside the compressed container
    bad = tmp_path / 'bad.blf'
    bad.write_bytes(bytes(data))
    with pytest.warns(CanLogWarning, match='unreadable after frame|not closed'):
        log = decode_log(bad)
    assert not log.complete and log.lines_skipped == 0
    k = len(log)
    assert k < r.sequence.size
    np.testing.assert_array_equal(log.sequence, r.sequence[:k])


# ---- damaged text logs: the bad line is skipped, the frames before and after it are kept ---------------------

TEXT_FORMATS = ('.asc', '.log')
TEXT_WRITERS = {'.asc': can.ASCWriter, '.log': can.CanutilsLogWriter}
N_FRAMES, BAD = 3085, 28     # once: 0 of 3085 frames decoded although the first 28 lines were intact
MARK = b'\xa5'               # data byte 0 of every frame: 'A5' in both formats, nowhere else on a frame line
GARBAGE = bytes((i * 73 + 29) % 256 for i in range(64)).replace(b'\n', b'')


def frame_key(m):
    return (m.timestamp, m.arbitration_id, m.is_extended_id, m.is_fd, m.bitrate_switch, m.is_rx, m.dlc,
            bytes(m.data), m.channel, m.is_remote_frame, m.is_error_frame)


def write_frames(path, n=N_FRAMES):
    """n frames through python-can's own writer: classic 0x123 (sent) and CAN FD 0x180 (received) in turn, the
    frame's index in data bytes 1-3. Returns python-can's reading of the good file and the file's lines."""
    with TEXT_WRITERS[path.suffix](str(path)) as w:
        for k in range(n):
            fd = k % 2 == 0
            data = MARK + k.to_bytes(3, 'big') + bytes(8 if fd else 4)
            w.on_message_received(can.Message(timestamp=1_767_000_000.0 + 1e-3 * k, arbitration_id=0x180 if fd
                                              else 0x123, is_extended_id=False, is_fd=fd, bitrate_switch=fd,
                                              is_rx=fd, data=data, channel='can0' if path.suffix == '.log' else 0))
    frames = read_plain(path)
    assert len(frames) == n
    return frames, path.read_bytes().split(b'\n')


def frame_lines(lines):
    """Indices of the frame lines (those with the MARK) among `lines`."""
    return [i for i, line in enumerate(lines) if b' A5' in line or b'#A5' in line or b'#1A5' in line]


def _flip_bit(line):        # bit 6 of the '5' of 'A5': 'u', no hex digit
    i = line.index(b'A5') + 1
    return line[:i] + bytes([line[i] ^ 0x40]) + line[i + 1:]


def _non_utf8(line):        # the 'A' of 'A5' becomes 0xff, which no UTF-8 text holds
    i = line.index(b'A5')
    return line[:i] + b'\xff' + line[i + 1:]


def _cut(line):             # the line ends one digit into the data, its newline kept
    return line[:line.index(b'A5') + 3]


def _time(line):            # the timestamp's decimal point becomes 'Q'
    return line.replace(b'.', b'Q', 1)


# name: (what is done at frame line BAD, frames lost, why the line is skipped (per format))
CORRUPTIONS = {
    'flipped bit': (lambda lines, i: lines[:i] + [_flip_bit(lines[i])] + lines[i + 1:], 1,
                    {'.asc': r'python-can cannot parse it \(ValueError', '.log': 'not a candump -L frame line'}),
    'non-UTF-8 byte': (lambda lines, i: lines[:i] + [_non_utf8(lines[i])] + lines[i + 1:], 1,
                       {'.asc': r'not UTF-8 text \(byte 0xff at column', '.log': r'not UTF-8 text \(byte 0xff'}),
    'truncated line': (lambda lines, i: lines[:i] + [_cut(lines[i])] + lines[i + 1:], 1,
                       {'.asc': r'data bytes where its length field says .* \(the line is cut short\)',
                        '.log': 'not a candump -L frame line'}),
    'damaged time': (lambda lines, i: lines[:i] + [_time(lines[i])] + lines[i + 1:], 1,
                     {'.asc': 'a damaged ASC frame line', '.log': 'not a candump -L frame line'}),
    'garbage line inserted': (lambda lines, i: lines[:i] + [GARBAGE] + lines[i:], 0,
                              {'.asc': 'not UTF-8 text', '.log': 'not UTF-8 text'}),
    'garbage over 3 lines': (lambda lines, i: lines[:i] + [lines[i][:20] + GARBAGE + lines[i + 2][20:]]
                             + lines[i + 3:], 3, {'.asc': 'not UTF-8 text', '.log': 'not UTF-8 text'}),
}


@pytest.mark.parametrize('suffix', TEXT_FORMATS)
@pytest.mark.parametrize('corruption', list(CORRUPTIONS))
def test_a_bad_line_costs_only_its_frames(tmp_path, suffix, corruption):
    """Once, one bad byte dropped every frame after it (and with a non-UTF-8 byte every frame before it as
    well). Now exactly the frames on the damaged line are missing; every frame before and after it is read,
    the skipped line is counted and named by number with the reason."""
    path = tmp_path / f'frames{suffix}'
    good, lines = write_frames(path)
    damage, lost, why = CORRUPTIONS[corruption]
    at = frame_lines(lines)[BAD]
    bad = tmp_path / f'bad{suffix}'
    bad.write_bytes(b'\n'.join(damage(lines, at)))
    reader = TextLogReader(bad)
    frames = [frame_key(m) for m in reader]
    expected = [frame_key(m) for m in good[:BAD] + good[BAD + lost:]]
    assert len(frames) == N_FRAMES - lost and frames[:BAD] == expected[:BAD]    # the 28 frames before it
    assert frames[BAD:] == expected[BAD:]                                     # and all 3057 (3055) after it
    assert reader.lines_skipped == 1 and reader.frames == N_FRAMES - lost
    (line_number, reason), = reader.skipped
    assert line_number == at + 1 and re.search(why[suffix], reason), reason
    # decode_log: the same frames, the skipped line counted and named in a warning with the file
    with pytest.warns(CanLogWarning) as caught:
        log = decode_log(bad)
    assert log.frames_total == N_FRAMES - lost and log.lines_skipped == 1 and not log.complete
    kept = good[:BAD] + good[BAD + lost:]
    assert log.frames_by_id == {0x123: sum(not m.is_fd for m in kept), 0x180: sum(m.is_fd for m in kept)}
    assert log.skipped_lines == [(at + 1, reason)]
    text = [str(w.message) for w in caught if 'skipped 1 unreadable line' in str(w.message)]
    assert len(text) == 1 and str(bad) in text[0] and f'line {at + 1}: ' in text[0], text
    assert f'the {N_FRAMES - lost} frames before and after them are decoded' in text[0]


@pytest.mark.parametrize('suffix', TEXT_FORMATS)
def test_a_good_text_log_reads_as_python_can_reads_it(logged_runs, suffix):
    """The line-by-line reader gives exactly can.LogReader's frames for a good log, and skips nothing."""
    _, path, _, _ = logged_runs[suffix]
    reader = TextLogReader(path)
    assert [frame_key(m) for m in reader] == [frame_key(m) for m in read_plain(path)]
    assert reader.lines_skipped == 0 and reader.skipped == [] and reader.frames > 1000
    log = decode_clean(path)
    assert log.lines_skipped == 0 and log.skipped_lines == [] and log.complete


@pytest.mark.parametrize('suffix', TEXT_FORMATS)
def test_a_bad_feedback_line_in_a_rig_log_costs_one_sample(logged_runs, tmp_path, suffix):
    """A rig log with a non-UTF-8 byte in one Feedback line decodes every other sample; the missing one shows as
    a sequence gap of one, and the warning names the line."""
    r, path, _, _ = logged_runs[suffix]
    lines = path.read_bytes().split(b'\n')
    feedback = re.compile(rb'\s180##' if suffix == '.log' else rb'CANFD\s+\d+\s+Rx\s+180\s')
    fb_lines = [i for i, line in enumerate(lines) if feedback.search(line)]
    assert len(fb_lines) == r.sequence.size
    j = len(fb_lines) // 2
    i = fb_lines[j]
    lines[i] = lines[i][:8] + b'\xfe' + lines[i][9:]
    bad = tmp_path / f'fb{suffix}'
    bad.write_bytes(b'\n'.join(lines))
    with pytest.warns(CanLogWarning, match=rf'skipped 1 unreadable line .*line {i + 1}: not UTF-8 text'):
        log = decode_log(bad)
    np.testing.assert_array_equal(log.sequence, np.delete(r.sequence, j))
    np.testing.assert_allclose(log.force, np.delete(r.force, j), rtol=0, atol=0.005)
    assert log.frames['Feedback'] == r.sequence.size - 1 and log.lines_skipped == 1
    assert [(g['expected'], g['lost']) for g in log.gaps] == [(r.sequence[j], 1)] and log.samples_lost == 1


@pytest.mark.parametrize('suffix', TEXT_FORMATS)
def test_many_bad_lines_are_all_counted_and_the_first_named(tmp_path, suffix):
    """Every 100th frame line damaged: all counted, the first MAX_SKIPPED_REPORTED kept with line numbers."""
    path = tmp_path / f'frames{suffix}'
    good, lines = write_frames(path)
    at = frame_lines(lines)[::100]
    for i in at:
        lines[i] = _flip_bit(lines[i])
    bad = tmp_path / f'bad{suffix}'
    bad.write_bytes(b'\n'.join(lines))
    with pytest.warns(CanLogWarning, match=rf'skipped {len(at)} unreadable lines .*\(and {len(at) - 3} more\)'):
        log = decode_log(bad)
    assert log.lines_skipped == len(at) == 31 and log.frames_total == N_FRAMES - len(at)
    assert [n for n, _ in log.skipped_lines] == [i + 1 for i in at[:MAX_SKIPPED_REPORTED]]
    assert [frame_key(m) for m in TextLogReader(bad)] == [frame_key(m) for k, m in enumerate(good) if k % 100]


@pytest.mark.parametrize('suffix', TEXT_FORMATS)
def test_a_text_log_with_nothing_readable_is_refused(tmp_path, suffix):
    """Every frame line damaged, or binary data in place of the log: refused, naming the file and the lines."""
    path = tmp_path / f'frames{suffix}'
    _, lines = write_frames(path, 40)
    for i in frame_lines(lines):
        lines[i] = _flip_bit(lines[i])
    bad = tmp_path / f'bad{suffix}'
    bad.write_bytes(b'\n'.join(lines))
    with pytest.raises(CanLogError, match=rf'{re.escape(str(bad))}: not a readable .* no frame could be read, '
                                          rf'40 of its \d+ lines are unreadable: line \d+: .*\(and 37 more\)'):
        decode_log(bad)
    binary = tmp_path / f'binary{suffix}'
    binary.write_bytes(GARBAGE * 50)
    with pytest.raises(CanLogError, match=rf'{re.escape(str(binary))}: .*line 1: not UTF-8 text'):
        decode_log(binary)
    prose = tmp_path / f'prose{suffix}'
    prose.write_text('this is no CAN log\nnor is this line\n')
    with pytest.raises(CanLogError, match=re.escape(str(prose))):
        decode_log(prose)
    assert cli_main(['canlog', str(bad)]) == 2


def test_cli_prints_the_skipped_line_count(logged_runs, tmp_path, capsys):
    _, path, _, _ = logged_runs['.log']
    assert cli_main(['canlog', str(path)]) == 0
    assert 'bad lines:  0 unreadable lines skipped' in capsys.readouterr().out
    lines = path.read_bytes().split(b'\n')
    lines[40] = b'(17.5) garbage that is no frame'
    lines[41] = lines[41][:10] + b'\x00' + lines[41][11:]
    bad = tmp_path / 'bad.log'
    bad.write_bytes(b'\n'.join(lines))
    assert cli_main(['canlog', str(bad)]) == 0
    captured = capsys.readouterr()
    assert 'bad lines:  2 unreadable lines skipped' in captured.out
    assert "  line 41: not a candump -L frame line: '(17.5) garbage that is no frame'" in captured.out
    assert '  line 42: binary data (byte 0x00 at column 11)' in captured.out
    assert 'INCOMPLETE' in captured.out and f'{bad} is incomplete: skipped 2 unreadable lines' in captured.err
    assert cli_main(['canlog', str(bad), '--json']) == 0
    info = json.loads(capsys.readouterr().out)
    assert info['lines_skipped'] == 2 and [s['line'] for s in info['skipped_lines']] == [41, 42]
    assert info['frames_total'] == len(read_plain(path)) - 2 and not info['complete']


def test_a_file_that_is_no_log_is_refused_with_its_name(tmp_path):
    path = tmp_path / 'text.blf'
    path.write_text('this is not a BLF file\n')
    with pytest.raises(ValueError, match='text.blf'):
        decode_log(path)


# ---- the command ---------------------------------------------------------------------------------------------

def test_cli_summary_json_and_csv(logged_runs, tmp_path, capsys):
    r, path, _, _ = logged_runs['.blf']
    out = tmp_path / 'samples.csv'
    assert cli_main(['canlog', str(path), '-o', str(out)]) == 0
    text = capsys.readouterr().out
    for needle in ('Feedback', 'Setpoint', 'duration:', 'gaps:       0 sequence gaps', 'faults:     none',
                   'bus load:', f'{r.sequence.size} (Feedback)'):
        assert needle in text, (needle, text)
    rows = np.genfromtxt(out, delimiter=',', names=True)
    np.testing.assert_array_equal(rows['sequence'], r.sequence)
    np.testing.assert_allclose(rows['force_N'], r.force, rtol=0, atol=0.005)
    assert cli_main(['canlog', str(path), '--json']) == 0
    info = json.loads(capsys.readouterr().out)
    assert info['frames']['Feedback'] == r.sequence.size and info['samples_lost'] == 0 and info['complete']


def test_cli_warns_on_a_truncated_log(logged_runs, tmp_path, capsys):
    _, path, _, _ = logged_runs['.log']
    cut = tmp_path / 'cut.log'
    cut.write_bytes(path.read_bytes()[:5000])
    assert cli_main(['canlog', str(cut)]) == 0
    captured = capsys.readouterr()
    assert 'INCOMPLETE' in captured.out and 'WARNING:' in captured.out and str(cut) in captured.err


@pytest.mark.skipif(not RUBBER_RIG.exists(), reason=f'{RUBBER_RIG} is not installed')
def test_cli_missing_file_exit_2_naming_it(tmp_path):
    missing = tmp_path / 'nothing.blf'
    proc = subprocess.run([str(RUBBER_RIG), 'canlog', str(missing)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert 'Traceback' not in proc.stderr
    assert str(missing) in proc.stderr.strip().splitlines()[-1]


def test_cli_unknown_suffix_exit_2(tmp_path, capsys):
    path = tmp_path / 'x.trc'
    path.write_text('')
    assert cli_main(['canlog', str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and '.blf' in err


@pytest.mark.ros
def test_rig_driver_node_reports_the_bus_profile_and_its_measured_load(ros_context):
    """can.* parameters reach the simulated bus: a classic 500 kbit/s bus with classic frames at 500 Hz needs
    43 % worst case; /diagnostics says so, with the load measured on the timed bus while the rig idles."""
    from rclpy.parameter import Parameter
    node_class = rig_driver_module().RigDriverNode
    node = node_class(context=ros_context, parameter_overrides=[
        Parameter('sample_rate', value=500.0), Parameter('can.fd', value=False),
        Parameter('can.bitrate', value=500_000), Parameter('can.profile', value='classic')])
    try:
        assert node.lifecycle_state == 'active' and node.rig.medium is not None
        assert node.rig.medium.bitrate == 500_000 and not node.rig.medium.fd
        assert node.rig.wait_ready(5.0)
        time.sleep(0.3)
        from rubber_rig.nodes.conversions import bus_lines
        diag = bus_lines(node.rig.driver, node.config.frame_profile)   # the bus's lines of /diagnostics
        assert diag['can_profile'] == 'classic' and 42.0 < float(diag['bus_load_pct']) < 44.0
        # idle: heartbeats, status and temperature only (about 80 frames/s of 8 bytes: ~2 % at 500 kbit/s)
        assert 0.5 < float(diag['bus_load_measured_pct']) < 12.0
        status = node.status_message()                      # RigStatus carries the measured load too
        assert status.bus_load == pytest.approx(float(diag['bus_load_measured_pct']) / 100, abs=0.01)
    finally:
        node.close()
        node.destroy_node()


# ---- the log's time: steps backwards and jumps are counted and named, the frames kept in file order -------------

def _frames_with_times(path, times):
    """One classic frame per time (0x123, its index in bytes 0-1) through python-can's writer of the suffix."""
    with can.Logger(str(path)) as w:
        for k, t in enumerate(times):
            w.on_message_received(can.Message(timestamp=t, arbitration_id=0x123, is_extended_id=False,
                                              data=k.to_bytes(2, 'big'), channel='can0' if path.suffix == '.log'
                                              else 0))


@pytest.mark.parametrize('suffix', TEXT_FORMATS)
def test_time_going_backwards_is_counted_named_and_kept_in_file_order(tmp_path, suffix):
    """The issue's case: one line's timestamp moved back 100 s gave 0 skipped lines, no warning and a -100 s step
    in `time`. Now the step is counted, named by frame and line in a CanLogWarning, and the frames stay in file
    order with their stamps as written (nothing dropped, nothing reordered). (ASC times count from the start of
    the log: there the line is moved back 0.1 s, to before its predecessor.)"""
    times = [1_767_000_000.0 + 0.01 * k for k in range(50)]
    path = tmp_path / f'back{suffix}'
    _frames_with_times(path, times)
    text = path.read_text()
    old, new, back = (('(1767000000.200000)', '(1766999900.200000)', 100.0) if suffix == '.log'
                      else (' 0.200000 ', ' 0.100000 ', 0.1))
    assert text.count(old) == 1
    path.write_text(text.replace(old, new))
    with pytest.warns(CanLogWarning, match=r'goes backwards 1 time .*frame 21 \(line \d+\): time goes back'):
        log = decode_log(path)
    assert log.frames_total == 50 and log.lines_skipped == 0 and not log.truncated
    assert (log.time_backwards, log.time_jumps, log.time_ok) == (1, 0, False)
    a = log.time_anomalies[0]
    assert (a.kind, a.frame) == ('backwards', 21) and a.step == pytest.approx(0.01 - back, abs=2e-3)
    data = '#0014' if suffix == '.log' else ' 00 14'           # frame 21 holds its index 20 (0x14)
    assert a.line == next(i for i, line in enumerate(path.read_text().splitlines(), 1) if data in line)
    ids = [int.from_bytes(bytes(m.data), 'big') for m in TextLogReader(path)]
    assert ids == list(range(50))                     # file order


@pytest.mark.parametrize('suffix', FORMATS)
def test_a_jump_in_time_is_counted_and_a_clean_log_has_none(tmp_path, suffix):
    """A hole of 30 s with no frame (a paused logger, a clock stepped forward) is a jump; 10 ms steps are not."""
    times = [1_767_000_000.0 + 0.01 * k + (30.0 if k >= 30 else 0.0) for k in range(50)]
    path = tmp_path / f'jump{suffix}'
    _frames_with_times(path, times)
    with pytest.warns(CanLogWarning, match=r'jumps forward 1 time by more than 10 s: frame 31'):
        log = decode_log(path)
    assert (log.time_backwards, log.time_jumps) == (0, 1)
    assert log.time_anomalies[0].step == pytest.approx(30.01, abs=2e-3)
    clean = tmp_path / f'clean{suffix}'
    _frames_with_times(clean, times[:30])
    log = decode_clean(clean)
    assert log.time_ok and log.time_anomalies == []


def test_the_time_check_counts_every_anomaly_and_names_the_first():
    check = TimeCheck(jump=1.0)
    for k, t in enumerate([0.0, 0.1, 0.05, 0.2, 5.0, 5.1, 4.0, 4.1, 20.0]):
        check.observe(t, k + 1, line=k + 3)
    assert (check.backwards, check.jumps) == (2, 2)
    assert [(a.kind, a.frame, a.line) for a in check.anomalies] == [
        ('backwards', 3, 5), ('jump', 5, 7), ('backwards', 7, 9), ('jump', 9, 11)]
    assert check.largest_back == pytest.approx(1.1)
    assert check.breaks == [3, 5, 7, 9]
    check.observe(1.0, 10)                  # back, and the way forward again after it: both cut the series
    check.observe(21.0, 11)
    assert check.breaks[-2:] == [10, 11] and (check.backwards, check.jumps) == (3, 2)


def test_cli_reports_time_anomalies_and_truncation(tmp_path, capsys):
    path = tmp_path / 'back.log'
    _frames_with_times(path, [1_767_000_000.0 + 0.01 * k for k in range(50)])
    path.write_text(path.read_text().replace('(1767000000.200000)', '(1766999900.200000)'))
    assert cli_main(['canlog', str(path)]) == 0
    captured = capsys.readouterr()
    assert 'time:       NOT MONOTONIC: 1 steps backwards, 0 jumps forward' in captured.out
    assert 'frame 21 (line 21): time goes back 99.99 s' in captured.out, captured.out
    assert 'goes backwards 1 times' in captured.err
    assert cli_main(['canlog', str(path), '--json']) == 0
    info = json.loads(capsys.readouterr().out)
    assert info['time_backwards'] == 1 and info['time_anomalies'][0]['frame'] == 21 and not info['truncated']
    cut = tmp_path / 'cut.log'
    text = path.read_text()
    cut.write_text(text[:text.rindex('#') + 3])      # the file ends inside its last frame line
    assert cli_main(['canlog', str(cut), '--json']) == 0
    info = json.loads(capsys.readouterr().out)
    assert info['truncated'] and info['lines_skipped'] == 1 and info['frames_total'] == 49


# ---- the log against the recording of the same run ------------------------------------------------------------

def _record_samples(path, log, keep):
    """The samples of `log` as the driver publishes them (RigSampleBatch of 20, stamped with the log's time), the
    batches for which keep(k) is True, recorded to an MCAP file by the Recorder."""
    rec = Recorder(path.parent)
    rec.start(path)
    n = len(log)
    for k, a in enumerate(range(0, n - n % 20, 20)):
        if not keep(k):
            continue
        t_ns = int(log.time_ns[a])
        msg = {'header': {'stamp': {'sec': t_ns // 10**9, 'nanosec': t_ns % 10**9}},
               'first_sequence': int(log.sequence[a]), 'sample_period': 1e-3,
               'displacement': log.displacement[a:a + 20], 'force': log.force[a:a + 20],
               'setpoint': log.setpoint[a:a + 20], 'temperature': 20.0, 'status_flags': 0, 'frames_lost': 0}
        assert rec.write('/rig/samples', 'msg_defs/msg/RigSampleBatch', msg, t_ns)
    rec.stop()


def test_the_log_is_compared_with_the_recording_of_the_run(logged_runs, tmp_path, capsys):
    _, path, _, _ = logged_runs['.log']
    log = decode_clean(path)
    _record_samples(tmp_path / 'rec', log, keep=lambda k: k != 5)      # the recorder lost batch 5 (20 samples)
    assert cli_main(['canlog', str(path), '--recording', str(tmp_path / 'rec'), '--json']) == 0
    c = json.loads(capsys.readouterr().out)['recording_comparison']
    whole = len(log) - len(log) % 20
    assert c['samples_both'] == whole - 20 and c['only_in_recording'] == 0
    assert c['only_in_log'] == len(log) - whole + 20 and c['first_only_in_log'] == int(log.sequence[100])
    # (the recording spreads a batch over its sample period from the first sample's stamp; the unpaced run's frames
    # came in bursts: milliseconds apart)
    assert c['values_agree'] and abs(c['time_offset_median']) < 0.05 and c['time_ok']
    # the same log with one line's time moved back 100 s: the comparison names the log's anomaly
    bad = tmp_path / 'back.log'
    lines = path.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if i > 300 and ' 180#' in line)
    stamp = lines[k][1:lines[k].index(')')]
    lines[k] = lines[k].replace(f'({stamp})', f'({float(stamp) - 100.0:.6f})')
    bad.write_text('\n'.join(lines) + '\n')
    assert cli_main(['canlog', str(bad), '--recording', str(tmp_path / 'rec')]) == 0
    out = capsys.readouterr().out
    assert f"WARNING:    the log's time goes backwards 1 times and jumps 0 times (frame {k + 1} (line {k + 1})" in out
    assert 'not the rig\'s clock' in out


def test_a_temperature_the_controller_does_not_have_reads_as_none_not_as_absolute_zero(tmp_path):
    """TEMP_Specimen's lowest raw value (-327.68 degC) says "no reading" (docs/protocol.md): the log reader gives
    NaN for it, as the driver does (issue 36: it read -327.68 degC as a temperature)."""
    from rubber_rig.rig.can.protocol import Protocol
    path, edited = tmp_path / 'run.blf', tmp_path / 'no_temperature.blf'
    assert run_program(PROG, dict(FAST, can_log=str(path))).completed
    proto, replaced = Protocol(), 0
    with can.Logger(str(edited)) as w:
        for msg in can.LogReader(str(path)):
            decoded = proto.decode(msg)
            if decoded and decoded[0] == 'Temperature':
                signals = dict(decoded[1], TEMP_Specimen=-327.68)
                new = proto.encode('Temperature', signals)
                msg = can.Message(timestamp=msg.timestamp, arbitration_id=new.arbitration_id, data=new.data,
                                  is_extended_id=False, is_rx=msg.is_rx, channel=msg.channel)
                replaced += 1
            w.on_message_received(msg)
    assert replaced >= 1
    normal, missing = decode_clean(path), decode_clean(edited)
    assert np.nanmin(normal.temperature) > 0.0
    assert np.isnan(missing.temperature).all(), np.unique(missing.temperature)
    np.testing.assert_array_equal(missing.sequence, normal.sequence)
