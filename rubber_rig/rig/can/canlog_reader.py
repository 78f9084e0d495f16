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

"""Reading raw CAN logs back: decode_log reads a log written by python-can (BLF, ASC, candump -L; see
:mod:`.canlog`) and decodes it with the project's DBC (cantools) into the numpy arrays a recording gives, with
frame counts, sequence gaps, faults and the bus load.

BLF is read with can.LogReader, up to the first object it cannot read. The text formats (.asc, .log) are read
line by line by TextLogReader, which hands each line to python-can's own parser and skips (and counts) a line
that is unreadable - not UTF-8, binary bytes, not a frame line of the format, a frame python-can cannot parse or
one with fewer data bytes than its length field says - so one bad line costs that line only.
"""
from __future__ import annotations

import collections
import errno
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import can
import numpy as np

from .canlog import SUPPORTED_FORMATS, CanLogError, CanLogWarning, log_format
from .canlog_text import TextLogReader, _asc_start, _integrity, frames_until_damage, text_damage
from .canlog_time import TimeCheck
from .frames import PROFILES, SampleFrames
from .protocol import DBC_PATH, STATES, STATUS_SEQ_MOD, MalformedFrame, Protocol, fault_names, meet, unwrap
from .protocol import temperature_reading as no_reading_is_nan
from .timing import frame_bits


@dataclass
class CanLog:
    """A raw CAN log decoded with the DBC. SI units; times in seconds since the log's first frame (`start`:
    its absolute timestamp [s since the epoch]; ASC logs carry it to the millisecond only).

    Samples (one per Feedback frame that advances the sequence; late or duplicated ones are counted in
    frames_late, as the driver does): sequence (unwrapped), time, time_ns (absolute), displacement [m], force [N],
    setpoint (the command the controller applied) [m], temperature [degC] and status (controller fault bits) of
    the latest Temperature / ControllerStatus frame before the sample - the arrays a recording gives.
    Host setpoints: setpoint_sequence, setpoint_time, setpoint_displacement. Controller: status_* (state code,
    index into STATES, fault bits, last consumed sequence, buffer level), heartbeat_time/heartbeat_state;
    commands: (time, command name, argument) of the host. gaps: sequence gaps while the controller was streaming
    ({'expected', 'received', 'lost', 'time'}); jumps: sequence jumps of an idle controller starting a new stream
    (not loss). frames: count per message name (unknown identifiers as '0x...'); frames_by_id: per identifier.
    complete is False when the log was damaged or not closed (warnings say how). A BLF log is decoded up to its
    damage; in a text log (.asc, .log) an unreadable line is skipped and the frames before and after it are
    decoded: lines_skipped counts the skipped lines, skipped_lines holds (line number, why) of the first
    MAX_SKIPPED_REPORTED. A skipped Feedback line shows as a sequence gap (its samples are missing from the data
    as if lost on the bus; the warning names the line). truncated: the file ends inside a line or record (cut
    short: a copy that stopped, a full disk, a writer killed mid-line), named in its own warning.
    Time (canlog_time.TimeCheck): a frame stamped before the one preceding it in the file (time_backwards) or more
    than canlog_time.JUMP_S after the latest before it (time_jumps) is an anomaly of the log; the frames stay in
    file order with their stamps as written (``time`` then steps back there) and time_anomalies names the first
    ones (frame number, line of a text log, step), with a warning. time_ok is False when there is any.
    """

    path: str
    format: str
    complete: bool = True
    warnings: list = field(default_factory=list)
    start: float = math.nan
    end: float = math.nan
    channels: list = field(default_factory=list)
    frames_total: int = 0
    frames_rx: int = 0
    frames_tx: int = 0
    frames: dict = field(default_factory=dict)
    frames_by_id: dict = field(default_factory=dict)
    frames_malformed: int = 0
    frames_unknown: int = 0
    error_frames: int = 0
    frames_late: int = 0
    lines_skipped: int = 0
    skipped_lines: list = field(default_factory=list)   # (line number, why) of the first MAX_SKIPPED_REPORTED
    truncated: bool = False               # the file ends inside a line or record (cut short)
    time_backwards: int = 0               # frames stamped before the frame preceding them in the file
    time_jumps: int = 0                   # gaps of more than canlog_time.JUMP_S with no frame
    time_anomalies: list = field(default_factory=list)   # canlog_time.TimeAnomaly of the first MAX_REPORTED
    sequence: np.ndarray = None
    time: np.ndarray = None
    time_ns: np.ndarray = None
    displacement: np.ndarray = None
    force: np.ndarray = None
    setpoint: np.ndarray = None
    temperature: np.ndarray = None
    status: np.ndarray = None
    setpoint_sequence: np.ndarray = None
    setpoint_time: np.ndarray = None
    setpoint_displacement: np.ndarray = None
    status_time: np.ndarray = None
    status_state: np.ndarray = None
    status_faults: np.ndarray = None
    status_last_sequence: np.ndarray = None
    status_buffer_level: np.ndarray = None
    heartbeat_time: np.ndarray = None
    heartbeat_state: np.ndarray = None
    commands: list = field(default_factory=list)
    gaps: list = field(default_factory=list)
    jumps: list = field(default_factory=list)
    samples_lost: int = 0
    faults: int = 0                       # union of the controller's fault bits
    states: list = field(default_factory=list)   # (time, state name) at each change of the controller state
    bits_nominal: int = 0                 # bits at the arbitration bit rate, summed over the frames
    bits_data: int = 0                    # bits in the CAN FD data phase (bit rate switch)

    @property
    def duration(self) -> float:
        return self.end - self.start if self.frames_total else 0.0

    @property
    def time_ok(self) -> bool:
        """True when the log's time only goes forward, without a jump (see canlog_time)."""
        return not (self.time_backwards or self.time_jumps)

    @property
    def faults_seen(self) -> list:
        return fault_names(self.faults)

    def __len__(self):
        return int(self.sequence.size)

    def bus_load(self, bitrate: float = 1_000_000, data_bitrate: float = 5_000_000) -> float:
        """Estimated bus load (0..1; above 1: the frames came faster than a real bus carries them, e.g. an
        unpaced simulated run): frame bits without bit stuffing (timing.frame_bits; stuffing adds up to about
        20 %) over the duration.
        """
        if not self.duration > 0:
            return math.nan
        return (self.bits_nominal / bitrate + self.bits_data / data_bitrate) / self.duration


def _frame_bits(msg: can.Message) -> tuple[int, int]:
    """(nominal, data-phase) bits of a logged frame, without bit stuffing."""
    return frame_bits(len(msg.data), fd=msg.is_fd, bitrate_switch=msg.bitrate_switch, worst_case=False,
                      extended=msg.is_extended_id)


def decode_log(path, dbc=DBC_PATH) -> CanLog:
    """Read the raw CAN log `path` (.blf, .asc or candump .log) and decode it with the DBC `dbc` (a path, or a
    Protocol) into a CanLog. BLF is read with can.LogReader: a damaged or unclosed BLF decodes up to the damage.
    .asc and .log are read with TextLogReader: an unreadable line is skipped and counted (CanLog.lines_skipped,
    skipped_lines) and the frames before and after it are decoded. Either way a CanLogWarning says what is
    missing and where (also in CanLog.warnings, complete=False). FileNotFoundError for a missing file,
    CanLogError for a file that is no log of its suffix's format, or a text log that holds no readable frame
    (every line with a frame in it unreadable, or no line of the format at all), naming the first bad lines.
    """
    p = Path(str(path)).expanduser()
    fmt = log_format(p)
    if not p.exists():
        raise FileNotFoundError(errno.ENOENT, 'no such CAN log', str(p))
    if p.is_dir():
        raise CanLogError(f'{p}: is a directory, not a CAN log')
    proto = dbc if isinstance(dbc, Protocol) else Protocol(dbc)
    out = CanLog(str(p), fmt)
    offset = 0.0
    if fmt == '.asc':   # relative times; the absolute start is in the trigger block header
        offset = _asc_start(p)
        if not math.isfinite(offset):
            offset = 0.0
            out.warnings.append(f'{p}: no readable "Begin Triggerblock" date: times are relative to the start of '
                                'the measurement, not absolute')
    if fmt == '.blf':
        try:
            reader = can.LogReader(str(p))
        except Exception as exc:   # noqa: BLE001 - python-can raises anything from struct.error to its own errors
            raise CanLogError(f'{p}: not a readable {SUPPORTED_FORMATS[fmt]} log: {exc or type(exc).__name__}') \
                from None
    else:
        reader = TextLogReader(p, fmt)
    try:
        _decode(reader, proto, out, offset)
    except _Damaged as exc:
        out.complete = False
        out.warnings.append(f'{p}: unreadable after frame {out.frames_total}: {exc.reason} (the frames before it '
                            'are decoded)')
    finally:
        try:
            reader.stop()
        except Exception:   # noqa: BLE001
            pass
    if isinstance(reader, TextLogReader):
        text_damage(p, reader, out)
    more = _integrity(p, fmt, reader, out.frames_total)
    if more:
        out.complete = False
        out.truncated = True
        out.warnings += more
    for text in out.warnings:
        warnings.warn(text, CanLogWarning, stacklevel=2)
    return out


class _Damaged(Exception):
    def __init__(self, reason):
        super().__init__(reason)
        self.reason = reason


# CanLog array -> dtype, filled from the lists of the same name while decoding
_ARRAYS = {
    'sequence': np.int64, 'time': float, 'displacement': float, 'force': float, 'setpoint': float,
    'temperature': float, 'status': np.uint32, 'setpoint_sequence': np.int64, 'setpoint_time': float,
    'setpoint_displacement': float, 'status_time': float, 'status_state': np.uint8, 'status_faults': np.uint32,
    'status_last_sequence': np.int64, 'status_buffer_level': np.int64, 'heartbeat_time': float,
    'heartbeat_state': np.uint8,
}


def _decode(reader, proto: Protocol, out: CanLog, offset: float = 0.0):
    """Decode every frame `reader` gives into `out` (timestamps shifted by `offset` [s]); what was decoded before
    a damaged stretch of the file is the result even then (_Damaged is raised after it is stored).
    """
    decoder = _Decoder(proto, out)
    if isinstance(reader, TextLogReader):
        decoder.line = lambda: reader.lines
    damaged = []
    try:
        for msg in frames_until_damage(reader, damaged):
            decoder.frame(msg, float(msg.timestamp) + offset)
        if damaged:
            raise _Damaged(damaged[0])
    finally:   # also after damage: what was decoded is the result
        decoder.finish()


class _Decoder:
    """The decoding state of one log: sequence unwrapping, the controller's state, the arrays being filled."""

    def __init__(self, proto: Protocol, out: CanLog):
        self.proto, self.out, self.by_id = proto, out, proto.by_id
        # a log does not say which frame profile the rig ran: each identifier says it (Setpoint serves two profiles)
        self.by_sample_id = {}
        for profile in PROFILES:
            sf = SampleFrames(profile, proto.db)
            for codec in sf.codecs.values():
                self.by_sample_id.setdefault(codec.frame_id, sf)
        self.last_fb = None   # (time, sequence) of the last sample of the previous feedback frame
        self.cmd_names = {int(k): str(v) for k, v in proto.by_name['HostCommand'].get_signal_by_name('CMD_Code')
                          .choices.items()}
        self.idle_states = {i for i, s in enumerate(STATES) if s not in ('running', 'holding', 'ramping_down')}
        self.frames, self.by_id_count, self.channels = collections.Counter(), collections.Counter(), {}
        self.a = collections.defaultdict(list)   # the arrays of _ARRAYS, as lists; 'time' holds absolute times
        self.expected = self.last_status_seq = self.sp_ref = self.state = None
        self.temperature, self.faults = math.nan, 0
        self.time_check = TimeCheck()
        self.line = lambda: None    # the line being read, for a text log

    def frame(self, msg, t: float) -> None:
        """Count and decode one frame received at log time t [s]."""
        out = self.out
        if not out.frames_total:
            out.start = t
        out.end = t
        out.frames_total += 1
        self.time_check.observe(t, out.frames_total, self.line())
        if msg.is_rx:
            out.frames_rx += 1
        else:
            out.frames_tx += 1
        self.channels[msg.channel] = None
        nominal, data = _frame_bits(msg)
        out.bits_nominal += nominal
        out.bits_data += data
        if msg.is_error_frame:
            out.error_frames += 1
            self.frames['error frame'] += 1
            return
        self.by_id_count[msg.arbitration_id] += 1
        sample_frames = None if msg.is_extended_id else self.by_sample_id.get(msg.arbitration_id)
        if sample_frames is not None:
            self._sample_frame(msg, sample_frames, t)
        else:
            self._other_frame(msg, t - out.start)

    def _sample_frame(self, msg, sample_frames, t: float) -> None:
        name = self.by_id[msg.arbitration_id].name
        self.frames[name] += 1
        rel = t - self.out.start
        try:
            if name not in sample_frames.feedback_names:
                seq, values = sample_frames.decode_setpoints(msg)
                self.sp_ref = unwrap(seq, self.sp_ref if self.sp_ref is not None else (self.expected or 0),
                                     sample_frames.setpoint_modulus)
                for i, v in enumerate(values):
                    self.a['setpoint_sequence'].append(self.sp_ref + i)
                    self.a['setpoint_time'].append(rel)
                    self.a['setpoint_displacement'].append(v)
                return
            samples = sample_frames.decode_feedback(msg)
        except MalformedFrame:
            self.out.frames_malformed += 1
            return
        if samples is not None:          # None: the first frame of a classic pair waits for its partner
            self._feedback(samples, sample_frames.feedback_modulus, t, rel)

    def _feedback(self, samples, modulus: int, t: float, rel: float) -> None:
        out, a = self.out, self.a
        seq, xs, fs, us = samples
        ref = self.expected if self.expected is not None else max(self.last_status_seq or 0, 0)
        s = unwrap(seq, ref, modulus)
        # a packed frame's samples were taken before it was sent: spread them back over the sample period
        # the frames' arrival times show
        last = s + len(xs) - 1
        # (not across a step back in the log's time: its samples keep the frame's stamp)
        period = (t - self.last_fb[0]) / (last - self.last_fb[1]) \
            if self.last_fb and last > self.last_fb[1] and t >= self.last_fb[0] else 0.0
        self.last_fb = (t, last)
        late, lost = meet(self.expected, s, len(xs))
        out.frames_late += late           # delayed or duplicated: their slots are already past (as the driver)
        if lost:
            gap = {'expected': self.expected, 'received': s, 'lost': lost, 'time': rel}
            if self.state in self.idle_states:
                out.jumps.append(gap)     # an idle controller started a new stream there: no loss
            else:
                out.gaps.append(gap)
                out.samples_lost += lost
        if late < len(xs):
            self.expected = last + 1
        for i in range(late, len(xs)):
            a['sequence'].append(s + i)
            a['time'].append(t - (len(xs) - 1 - i) * period)
            a['displacement'].append(xs[i])
            a['force'].append(fs[i])
            a['setpoint'].append(us[i])
            a['temperature'].append(self.temperature)
            a['status'].append(self.faults)

    def _other_frame(self, msg, rel: float) -> None:
        out, a = self.out, self.a
        try:
            decoded = self.proto.decode(msg)
        except MalformedFrame:
            out.frames_malformed += 1
            m = self.by_id.get(msg.arbitration_id)
            self.frames[m.name if m else f'0x{msg.arbitration_id:x}'] += 1
            return
        if decoded is None:
            out.frames_unknown += 1
            self.frames[f'0x{msg.arbitration_id:x}'] += 1
            return
        name, sig = decoded
        self.frames[name] += 1
        if name == 'ControllerStatus':
            code, self.faults = int(sig['ST_State']), int(sig['ST_Faults'])
            out.faults |= self.faults
            self.last_status_seq = unwrap(int(sig['ST_LastSequence']), self.last_status_seq
                                          if self.last_status_seq is not None else (self.expected or 0),
                                          STATUS_SEQ_MOD)
            a['status_time'].append(rel)
            a['status_state'].append(code)
            a['status_faults'].append(self.faults)
            a['status_last_sequence'].append(self.last_status_seq)
            a['status_buffer_level'].append(int(sig['ST_BufferLevel']))
            self.state = _state_change(out, self.state, code, rel)
        elif name == 'ControllerHeartbeat':
            code = int(sig['HB_State'])
            a['heartbeat_time'].append(rel)
            a['heartbeat_state'].append(code)
            self.state = _state_change(out, self.state, code, rel)
        elif name == 'Temperature':
            self.temperature = no_reading_is_nan(float(sig['TEMP_Specimen']))   # NaN: the controller has none
        elif name == 'HostCommand':
            code = int(sig['CMD_Code'])
            out.commands.append((rel, self.cmd_names.get(code, str(code)), float(sig['CMD_Argument'])))

    def finish(self) -> None:
        """Store the counts and arrays in the CanLog (times relative to its start; time_ns absolute)."""
        out = self.out
        out.frames = dict(self.frames)
        out.frames_by_id = dict(sorted(self.by_id_count.items()))
        out.channels = [c for c in self.channels if c is not None]
        for key, dtype in _ARRAYS.items():
            setattr(out, key, np.asarray(self.a[key], dtype=dtype))
        t = out.time
        out.time_ns = np.round(t * 1e9).astype(np.int64)
        out.time = t - out.start if t.size else t
        check = self.time_check
        out.time_backwards, out.time_jumps, out.time_anomalies = check.backwards, check.jumps, list(check.anomalies)
        if check.count:
            out.warnings.append(check.warning(out.path))


def _state_change(out: CanLog, state, code, rel):
    if code != state:
        out.states.append((rel, STATES[code] if code < len(STATES) else f'state {code}'))
    return code
