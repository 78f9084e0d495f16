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
that is unreadable - not UTF-8, binary bytes, not a frame line of the format, a frame python-can cannot parse
or one with fewer data bytes than its length field says - so one bad line costs that line only: every good
frame before and after it is decoded.
"""
from __future__ import annotations

import collections
import errno
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import can
import numpy as np
from can.io.asc import ASC_MESSAGE_REGEX

from .canlog import SUPPORTED_FORMATS, CanLogError, CanLogWarning, log_format
from .frames import PROFILES, SampleFrames
from .protocol import DBC_PATH, STATES, STATUS_SEQ_MOD, MalformedFrame, Protocol, fault_names, unwrap
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
    as if lost on the bus; the warning names the line).
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


_ASC_TRIGGER = re.compile(rb'begin\s+triggerblock\s+\w+\s+(?P<when>.+)', re.IGNORECASE)
_ASC_MILLISECONDS = re.compile(r'(\d{1,2}:\d{2}:\d{2})\.(\d{1,3})(?!\d)')


def _asc_start(path: Path) -> float:
    """Absolute time [s since the epoch] of an ASC log's first trigger block, NaN if it has none.

    ASC times are relative to it. It carries milliseconds, which python-can's ASCWriter writes without leading
    zeros ('.40' for 40 ms) and its reader takes for a decimal fraction (0.40 s); CANoe writes three digits. Read
    here as a count of milliseconds, right for both.
    """
    with open(path, 'rb') as f:
        for _, line in zip(range(100), f, strict=False):
            m = _ASC_TRIGGER.match(line.strip())
            if m:
                when = _ASC_MILLISECONDS.sub(lambda g: f'{g.group(1)}.{g.group(2).zfill(3)}',
                                             m.group('when').decode('utf-8', 'replace').strip())
                try:
                    return can.ASCReader._datetime_to_timestamp(when)
                except ValueError:
                    return math.nan
    return math.nan


def _integrity(path: Path, fmt: str, reader, frames: int) -> list:
    """Signs that a log was not closed or is cut short that its reader passes over silently."""
    out = []
    size = path.stat().st_size
    if fmt == '.blf':
        header_size, objects = getattr(reader, 'file_size', size), getattr(reader, 'object_count', frames)
        if header_size != size or objects != frames:
            out.append(f'{path}: BLF header says {objects} objects in {header_size} bytes, the file has {frames} '
                       f'frames in {size} bytes: the log was not closed (writer killed) or is truncated')
        return out
    with open(path, 'rb') as f:
        f.seek(max(0, size - 64))
        tail = f.read()
    if size and not tail.endswith(b'\n'):
        out.append(f'{path}: the last line is incomplete: the log is truncated')
    if fmt == '.asc' and b'end triggerblock' not in tail.lower():
        out.append(f'{path}: no "End TriggerBlock": the log was not closed (writer killed) or is truncated')
    return out


# ---------------------------------------------------------------------------------------- text logs, line by line
MAX_SKIPPED_REPORTED = 10   # skipped lines whose number and reason are kept (all of them are counted)
_WARNED_SKIPPED = 3         # of those, named in the warning
_FD_LENGTHS = frozenset((*range(9), 12, 16, 20, 24, 32, 48, 64))
_CONTROL = re.compile(r'[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]')   # never in a text log (tab and CR are)
# candump -L (can-utils, python-can's CanutilsLogWriter): '(time) channel id#data', id of 3 (standard) or 8
# (extended) hex digits, '##<flags>' before the data of a CAN FD frame, 'R[dlc]' for a remote frame, and
# python-can's optional direction ' R' (received) / ' T' (sent)
_CANDUMP_FRAME = re.compile(r'\(\d+(?:\.\d*)?\)\s+\S+\s+(?:[0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})#(?:#[0-9A-Fa-f])?'
                            r'(?:(?:[0-9A-Fa-f]{2})*|[Rr]\d*)(?:\s+[RrTt])?')
# an ASC line laid out as a frame whatever its fields hold: 'CANFD' as its second or third word, or a 5-letter
# word in its place before '<channel> Rx|Tx' (a damaged 'CANFD'), or a lower-case data type 'd' / 'r' with a 1-2
# digit length after 3 to 5 words ('<time> <channel> <id> <dir> d <dlc> ...', one word more or less when a
# damaged byte split or joined two). When python-can's pattern (ASC_MESSAGE_REGEX) does not match such a line,
# python-can passes over it in silence: a frame whose time, channel, direction or CANFD mark is damaged would
# vanish uncounted. CANoe's other lines are not laid out so ('Statistic: D 0 R 0 ...' has upper-case letters,
# J1939TP lines have 'd' after 9 words, LIN lines 'Li <id> Rx').
_ASC_FRAME_SHAPE = re.compile(r'(?:\S+\s+){1,2}CANFD\s|\S+\s+\S{5}\s+\d+\s+[RT]x\s'
                              r'|(?:\S+\s+){3,5}[dr]\s+[0-9A-Fa-f]{1,2}(?:\s|$)')
_ASC_HEADER = re.compile(r'(?:date|base|begin\s+triggerblock|end\s+triggerblock|(?:no\s+)?internal\s+events)\b',
                         re.IGNORECASE)


def _shown(line, limit: int = 60) -> str:
    """A line (str, or bytes that are no text) as a warning shows it: repr, cut to `limit` characters."""
    line = line.strip()
    return repr(line[:limit]) + ('...' if len(line) > limit else '')


def _frame_problem(msg: can.Message):
    """Why a frame python-can read from a text line cannot be one (None if it can): fewer data bytes than its
    length field says (a line cut short), more than 8 in a classic frame, no CAN FD length.
    """
    if msg.is_error_frame or msg.is_remote_frame:
        return None
    n = len(msg.data)
    expected = msg.dlc if msg.is_fd else min(msg.dlc, 8)
    if n < expected:
        return f'{n} data bytes where its length field says {expected} (the line is cut short)'
    if not msg.is_fd and n > 8:
        return f'{n} data bytes in a classic CAN frame (at most 8)'
    if msg.is_fd and n not in _FD_LENGTHS:
        return f'{n} data bytes is no CAN FD frame length'
    return None


class _ASCLineParser(can.ASCReader):
    """python-can's ASCReader reading its header once: iterated again after a line it could not parse, it goes on
    with the next line instead of taking that line for the header (overrides its _extract_header).
    """

    _header_read = False

    def _extract_header(self) -> None:
        if not self._header_read:
            self._header_read = True
            super()._extract_header()


class _Lines:
    """The lines of a text log for a python-can reader (which iterates its `file`): each line is checked first
    and an unreadable one is skipped and counted in the TextLogReader instead of reaching the parser.
    """

    def __init__(self, raw, owner: TextLogReader):
        self.raw, self.owner = iter(raw), owner
        self.text = ''   # the last line handed to the parser

    def __iter__(self):
        return self

    def __next__(self) -> str:
        owner = self.owner
        for raw in self.raw:
            owner.lines += 1
            try:
                text = raw.decode('utf-8')
            except UnicodeDecodeError as exc:
                owner.skip(f'not UTF-8 text (byte 0x{raw[exc.start]:02x} at column {exc.start + 1}): {_shown(raw)}')
                continue
            bad = _CONTROL.search(text)
            if bad:
                owner.skip(f'binary data (byte 0x{ord(bad.group()):02x} at column {bad.start() + 1}): '
                           f'{_shown(text)}')
                continue
            line = text.strip()
            if not line:
                continue
            why = owner.check(line)
            if why:
                owner.skip(f'{why}: {_shown(line)}')
                continue
            self.text = line
            return text
        raise StopIteration

    def close(self):
        """python-can closes its file at the end; the TextLogReader closes the real one."""


class TextLogReader:
    """The frames (can.Message) of a text CAN log - .asc (Vector ASC) or .log (candump -L) - resynchronised
    after damage: the file is read line by line as bytes and python-can's own parser (can.ASCReader,
    can.CanutilsLogReader) reads each good line, so a good log gives exactly what can.LogReader gives.

    A line is skipped and counted, and the frames before and after it are kept, when it is:

    - not UTF-8 text, or holds binary bytes (control characters other than tab and CR);
    - .log: not a candump -L frame line '(time) channel id#data [R|T]' (a flipped byte, a cut line, garbage);
    - .asc: laid out as a frame line ('<time> <channel> <id> <dir> d|r <dlc> <data>', '<time> CANFD ...') but
      not one python-can recognises (damaged time, channel or direction: python-can would drop it silently);
      other ASC lines (header, comments, statistics, events) are python-can's to read or pass over;
    - a frame line python-can's parser raises on (a damaged identifier, length or data byte);
    - a frame with fewer data bytes than its length field says, more than 8 in a classic frame, or a length no
      CAN FD frame has (a line cut short).

    Iterate once. Counts: lines (read), lines_skipped, frames; skipped: (line number, why) of the first
    MAX_SKIPPED_REPORTED skipped lines; header_lines: ASC header/trigger block lines seen.
    """

    def __init__(self, path, fmt: str = None):
        self.path = Path(str(path)).expanduser()
        self.format = fmt or log_format(self.path)
        if self.format not in ('.asc', '.log'):
            raise CanLogError(f'{self.path}: {SUPPORTED_FORMATS.get(self.format, self.format)} is no text log')
        self.lines = self.lines_skipped = self.frames = self.header_lines = 0
        self.skipped = []

    def skip(self, why: str):
        """Count the line being read as skipped for the reason `why`."""
        self.lines_skipped += 1
        if len(self.skipped) < MAX_SKIPPED_REPORTED:
            self.skipped.append((self.lines, why))

    def check(self, line: str):
        """Why the stripped, non-empty text line `line` is no line of the format (None if it may be one)."""
        if self.format == '.log':
            return None if _CANDUMP_FRAME.fullmatch(line) else 'not a candump -L frame line'
        if _ASC_HEADER.match(line):
            self.header_lines += 1
        elif (not line.startswith('//') and _ASC_FRAME_SHAPE.match(line)
              and not ASC_MESSAGE_REGEX.match(line)):
            return 'a damaged ASC frame line (time, channel or direction unreadable)'
        return None

    def skipped_text(self, limit: int = _WARNED_SKIPPED) -> str:
        """'line 29: why; line 40: why (and 3 more)' of the first `limit` skipped lines."""
        text = '; '.join(f'line {n}: {why}' for n, why in self.skipped[:limit])
        more = self.lines_skipped - min(limit, len(self.skipped))
        return text + (f' (and {more} more)' if more else '')

    def __iter__(self):
        with open(self.path, 'rb') as f:
            lines = _Lines(f, self)
            parser = _ASCLineParser(lines) if self.format == '.asc' else can.CanutilsLogReader(lines)
            while True:
                try:
                    for msg in parser:   # a fresh iteration after a line python-can raised on goes on after it
                        problem = _frame_problem(msg)
                        if problem:
                            self.skip(f'{problem}: {_shown(lines.text)}')
                            continue
                        self.frames += 1
                        yield msg
                    return
                except OSError:
                    raise
                except Exception as exc:   # noqa: BLE001 - python-can's parsers raise anything on a bad line
                    self.skip(f'python-can cannot parse it ({type(exc).__name__}: {exc}): {_shown(lines.text)}')

    def stop(self):
        """As python-can's readers (the file is closed when the iteration ends)."""


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
        _text_damage(p, reader, out)
    more = _integrity(p, fmt, reader, out.frames_total)
    if more:
        out.complete = False
        out.warnings += more
    for text in out.warnings:
        warnings.warn(text, CanLogWarning, stacklevel=2)
    return out


def _text_damage(p: Path, reader: TextLogReader, out: CanLog):
    """The skipped lines of a text log into `out`; CanLogError if nothing in the file could be read."""
    out.lines_skipped, out.skipped_lines = reader.lines_skipped, list(reader.skipped)
    name = SUPPORTED_FORMATS[out.format]
    if not out.frames_total:
        if reader.lines_skipped:
            raise CanLogError(f'{p}: not a readable {name} log: no frame could be read, {reader.lines_skipped} of '
                              f'its {reader.lines} lines are unreadable: {reader.skipped_text()}')
        if out.format == '.asc' and not reader.header_lines and p.stat().st_size:
            raise CanLogError(f'{p}: not a readable {name} log: none of its {reader.lines} lines is an ASC header '
                              'or frame line')
    if reader.lines_skipped:
        out.complete = False
        s = '' if reader.lines_skipped == 1 else 's'
        out.warnings.append(f'{p}: skipped {reader.lines_skipped} unreadable line{s} of {reader.lines} '
                            f'(the {out.frames_total} frames before and after them are decoded): '
                            f'{reader.skipped_text()}')


def frames_until_damage(reader, damaged: list):
    """The frames of a python-can log reader up to the first it cannot read (corrupt data: what precedes it is
    good); why it stopped is appended to `damaged`, which stays empty when the log was read to its end.
    """
    it = iter(reader)
    while True:
        try:
            msg = next(it)
        except StopIteration:
            return
        except Exception as exc:   # noqa: BLE001 - python-can's readers raise anything on corrupt data
            damaged.append(f'{type(exc).__name__}: {exc}')
            return
        yield msg


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
    by_id = proto.by_id
    # a log does not say which frame profile the rig ran: each identifier says it (Setpoint serves two profiles)
    by_sample_id = {}
    for profile in PROFILES:
        sf = SampleFrames(profile, proto.db)
        for codec in sf.codecs.values():
            by_sample_id.setdefault(codec.frame_id, sf)
    last_fb = None   # (time, sequence) of the last sample of the previous feedback frame
    cmd_names = {int(k): str(v) for k, v in proto.by_name['HostCommand'].get_signal_by_name('CMD_Code')
                 .choices.items()}
    idle_states = {i for i, s in enumerate(STATES) if s not in ('running', 'holding', 'ramping_down')}
    frames, by_id_count, channels = collections.Counter(), collections.Counter(), {}
    a = collections.defaultdict(list)   # the arrays of _ARRAYS, as lists; 'time' holds absolute timestamps
    expected = last_status_seq = sp_ref = state = None
    temperature, faults = math.nan, 0
    damaged = []
    try:
        for msg in frames_until_damage(reader, damaged):
            t = float(msg.timestamp) + offset
            if not out.frames_total:
                out.start = t
            out.end = t
            rel = t - out.start
            out.frames_total += 1
            if msg.is_rx:
                out.frames_rx += 1
            else:
                out.frames_tx += 1
            channels[msg.channel] = None
            nominal, data = _frame_bits(msg)
            out.bits_nominal += nominal
            out.bits_data += data
            if msg.is_error_frame:
                out.error_frames += 1
                frames['error frame'] += 1
                continue
            by_id_count[msg.arbitration_id] += 1
            sample_frames = None if msg.is_extended_id else by_sample_id.get(msg.arbitration_id)
            if sample_frames is not None:
                name = by_id[msg.arbitration_id].name
                frames[name] += 1
                try:
                    if name in sample_frames.feedback_names:
                        samples = sample_frames.decode_feedback(msg)
                    else:
                        seq, values = sample_frames.decode_setpoints(msg)
                        samples = None
                        sp_ref = unwrap(seq, sp_ref if sp_ref is not None else (expected or 0),
                                        sample_frames.setpoint_modulus)
                        for i, v in enumerate(values):
                            a['setpoint_sequence'].append(sp_ref + i)
                            a['setpoint_time'].append(rel)
                            a['setpoint_displacement'].append(v)
                except MalformedFrame:
                    out.frames_malformed += 1
                    continue
                if samples is None:
                    continue
                seq, xs, fs, us = samples
                ref = expected if expected is not None else max(last_status_seq or 0, 0)
                s = unwrap(seq, ref, sample_frames.feedback_modulus)
                # a packed frame's samples were taken before it was sent: spread them back over the sample period
                # the frames' arrival times show
                last = s + len(xs) - 1
                period = (t - last_fb[0]) / (last - last_fb[1]) if last_fb and last > last_fb[1] else 0.0
                last_fb = (t, last)
                for i in range(len(xs)):
                    if expected is not None and s + i < expected:
                        out.frames_late += 1      # delayed or duplicated: its slot is already past (as the driver)
                        continue
                    if expected is not None and s + i > expected:
                        gap = {'expected': expected, 'received': s + i, 'lost': s + i - expected, 'time': rel}
                        if state in idle_states:
                            out.jumps.append(gap)    # an idle controller started a new stream there: no loss
                        else:
                            out.gaps.append(gap)
                            out.samples_lost += s + i - expected
                    expected = s + i + 1
                    a['sequence'].append(s + i)
                    a['time'].append(t - (len(xs) - 1 - i) * period)
                    a['displacement'].append(xs[i])
                    a['force'].append(fs[i])
                    a['setpoint'].append(us[i])
                    a['temperature'].append(temperature)
                    a['status'].append(faults)
                continue
            try:
                decoded = proto.decode(msg)
            except MalformedFrame:
                out.frames_malformed += 1
                m = by_id.get(msg.arbitration_id)
                frames[m.name if m else f'0x{msg.arbitration_id:x}'] += 1
                continue
            if decoded is None:
                out.frames_unknown += 1
                frames[f'0x{msg.arbitration_id:x}'] += 1
                continue
            name, sig = decoded
            frames[name] += 1
            if name == 'ControllerStatus':
                code, faults = int(sig['ST_State']), int(sig['ST_Faults'])
                out.faults |= faults
                last_status_seq = unwrap(int(sig['ST_LastSequence']), last_status_seq if last_status_seq is not None
                                         else (expected or 0), STATUS_SEQ_MOD)
                a['status_time'].append(rel)
                a['status_state'].append(code)
                a['status_faults'].append(faults)
                a['status_last_sequence'].append(last_status_seq)
                a['status_buffer_level'].append(int(sig['ST_BufferLevel']))
                state = _state_change(out, state, code, rel)
            elif name == 'ControllerHeartbeat':
                code = int(sig['HB_State'])
                a['heartbeat_time'].append(rel)
                a['heartbeat_state'].append(code)
                state = _state_change(out, state, code, rel)
            elif name == 'Temperature':
                temperature = float(sig['TEMP_Specimen'])
            elif name == 'HostCommand':
                code = int(sig['CMD_Code'])
                out.commands.append((rel, cmd_names.get(code, str(code)), float(sig['CMD_Argument'])))
        if damaged:
            raise _Damaged(damaged[0])
    finally:   # also after damage: what was decoded is the result
        out.frames = dict(frames)
        out.frames_by_id = dict(sorted(by_id_count.items()))
        out.channels = [c for c in channels if c is not None]
        for key, dtype in _ARRAYS.items():
            setattr(out, key, np.asarray(a[key], dtype=dtype))
        t = out.time
        out.time_ns = np.round(t * 1e9).astype(np.int64)
        out.time = t - out.start if t.size else t


def _state_change(out: CanLog, state, code, rel):
    if code != state:
        out.states.append((rel, STATES[code] if code < len(STATES) else f'state {code}'))
    return code
