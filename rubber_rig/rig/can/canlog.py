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

"""Raw CAN logs the way CAN engineers expect them: every frame the host driver sends and receives, written by
python-can's can.Logger (Vector BLF, Vector ASC or candump -L, chosen by the file name), and decode_log, which
reads such a log with can.LogReader and decodes it with the project's DBC (cantools) into numpy arrays.

Writing (RigConfig.can_log; open_rig wraps the driver's bus in a LoggingBus):

- tx = sent by the host (the driver), stamped with the wall clock (time.time()) when the bus accepted it;
  rx = received by the host, stamped with the bus's own receive timestamp (python-can interfaces give seconds
  since the epoch; a frame without one gets the wall clock when the driver read it, and an interface on another
  clock is shifted onto the wall clock at its first frame). Every frame carries the one channel name of the
  log: the configured CAN channel, else 'sim0' for the in-process simulated rig and '<backend>0' for other
  interfaces (BLF and ASC store channel numbers: the name's trailing digits + 1).
- The driver drains received frames only when it polls, so a received frame can be older than a frame sent
  just before; frames are held back REORDER_WINDOW seconds and written in timestamp order (candump -L and ASC
  writers need non-decreasing times).
- Writing happens in a thread of its own, so the driver never waits for the disk. A write error never
  stops the rig: it is counted and reported once (on_error, then the log's `error`); frames beyond
  MAX_QUEUED waiting to be written are dropped and counted.
- The log is flushed every second and closed (all frames written, BLF header completed) with the rig:
  Rig.close(), the driver's close and the bus's shutdown; also at interpreter exit if the rig never closed.
"""
from __future__ import annotations

import collections
import errno
import heapq
import itertools
import logging
import math
import os
import re
import threading
import time
import warnings
import weakref
from dataclasses import dataclass, field
from pathlib import Path

import can
import numpy as np

from .protocol import DBC_PATH, STATES, MalformedFrame, Protocol, fault_names, unwrap_sequence
from .timing import frame_bits

_log = logging.getLogger(__name__)

# the formats whose python-can writer and reader keep what a rig log needs: direction (Tx/Rx), CAN FD and
# bit-rate-switch flags, channel and timestamps (.csv, .db and .trc lose the direction or the FD flags)
SUPPORTED_FORMATS = {
    '.blf': 'Vector BLF',
    '.asc': 'Vector ASC',
    '.log': 'candump -L',
}
REORDER_WINDOW = 1.0     # [s] frames are held this long and written in timestamp order
FLUSH_PERIOD = 1.0       # [s] the file is flushed this often
MAX_QUEUED = 500_000     # frames waiting to be written beyond this are dropped (counted)
LOG_CHANNEL_SIM = 'sim0'  # channel name of the in-process simulated rig's bus in the log
MAX_CLOCK_OFFSET = 60.0  # [s] received timestamps further from the wall clock are on another clock


class CanLogError(ValueError):
    """A CAN log cannot be written (bad suffix, unwritable place) or read (not a log of a supported format)."""


class CanLogWarning(UserWarning):
    """A CAN log was read only in part (truncated, not closed, corrupt): the data before the damage is decoded."""


def _supported_text() -> str:
    return ', '.join(f'{suffix} ({name})' for suffix, name in SUPPORTED_FORMATS.items())


def log_format(path) -> str:
    """The suffix of a supported CAN log file name ('.blf', '.asc', '.log'); CanLogError names the supported
    ones otherwise. Checks the name only.
    """
    suffix = Path(str(path)).suffix.lower()
    if suffix not in SUPPORTED_FORMATS:
        what = f'unsupported suffix {suffix!r}' if suffix else 'no suffix'
        raise CanLogError(f'{path}: {what}: the file name chooses the CAN log format; supported: '
                          f'{_supported_text()}')
    return suffix


def check_log_path(path) -> Path:
    """Check that a CAN log can be written at `path` (supported suffix, existing writable directory, not a
    directory itself) without creating anything; CanLogError says what is wrong. Returns the path.
    """
    log_format(path)
    p = Path(str(path)).expanduser()
    parent = p.parent
    if p.is_dir():
        raise CanLogError(f'{p}: is a directory, not a CAN log file name')
    if not parent.exists():
        raise CanLogError(f'{p}: directory {parent} does not exist')
    if not parent.is_dir():
        raise CanLogError(f'{p}: {parent} is not a directory')
    if not os.access(parent, os.W_OK | os.X_OK):
        raise CanLogError(f'{p}: directory {parent} is not writable')
    if p.exists() and not os.access(p, os.W_OK):
        raise CanLogError(f'{p}: file exists and is not writable')
    return p


def _log_copy(msg: can.Message, timestamp: float, is_rx: bool, channel) -> can.Message:
    """The frame as it goes to the log (the driver's and the bus's Message objects are never modified)."""
    return can.Message(timestamp=timestamp, arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                       is_remote_frame=msg.is_remote_frame, is_error_frame=msg.is_error_frame, channel=channel,
                       dlc=msg.dlc, data=bytes(msg.data), is_fd=msg.is_fd, is_rx=is_rx,
                       bitrate_switch=msg.bitrate_switch, error_state_indicator=msg.error_state_indicator,
                       check=False)


class _Writer:
    """The writing thread's side of a CanLogTap (no reference back to the tap, so the tap can be collected
    and its finalizer close the file).
    """

    def __init__(self, writer, path, on_error):
        self.writer, self.path, self.on_error = writer, path, on_error
        self.queue = collections.deque()   # frames handed over by the driver's thread (append is thread-safe)
        self.heap = []                     # (timestamp, order, message) waiting for the reorder window
        self.order = itertools.count()
        self.frames_written = self.write_errors = self.frames_dropped = self.frames_out_of_order = 0
        self.error = ''
        self.last_written = -math.inf
        self.stop_event = threading.Event()
        self.closed = False
        self.lock = threading.Lock()
        self.report_lock = threading.Lock()
        self.thread = threading.Thread(target=self._run, name=f'can_log {Path(path).name}', daemon=True)
        self.thread.start()

    def _failed(self, what: str, exc: BaseException):
        with self.report_lock:
            self.write_errors += 1
            if self.error:   # reported once
                return
            self.error = f'raw CAN log {self.path}: {what}: {exc} (the rig keeps running; frames not written ' \
                         'are counted)'
        try:
            if self.on_error is not None:
                self.on_error(self.error)
            else:
                _log.warning(self.error)
        except Exception:   # noqa: BLE001 - reporting must not break the log either
            pass

    def _take(self):
        queue, heap, order = self.queue, self.heap, self.order
        while queue:
            msg = queue.popleft()
            heapq.heappush(heap, (msg.timestamp, next(order), msg))

    def _write_until(self, limit: float):
        heap = self.heap
        write = self.writer.on_message_received
        while heap and heap[0][0] <= limit:
            ts, _, msg = heapq.heappop(heap)
            if ts < self.last_written:
                self.frames_out_of_order += 1   # arrived later than the reorder window: written as it is
            else:
                self.last_written = ts
            try:
                write(msg)
                self.frames_written += 1
            except Exception as exc:   # noqa: BLE001 - disk full, I/O error: counted, the rig is not stopped
                self._failed('write failed', exc)

    def _flush_file(self):
        f = getattr(self.writer, 'file', None)
        if f is not None and not f.closed:
            try:
                f.flush()
            except Exception as exc:   # noqa: BLE001
                self._failed('flush failed', exc)

    def _run(self):
        next_flush = time.monotonic() + FLUSH_PERIOD
        while not self.stop_event.wait(0.05):
            try:
                self._take()
                self._write_until(time.time() - REORDER_WINDOW)
                if time.monotonic() >= next_flush:
                    self._flush_file()
                    next_flush = time.monotonic() + FLUSH_PERIOD
            except Exception as exc:   # noqa: BLE001 - the thread must outlive anything a writer raises
                self._failed('writer failed', exc)

    def close(self, timeout: float = 30.0):
        """Write every frame still held, complete and close the file (idempotent, any thread)."""
        with self.lock:
            if self.closed:
                return
            self.closed = True
        self.stop_event.set()
        if self.thread is not threading.current_thread():
            self.thread.join(timeout)
            if self.thread.is_alive():   # stuck in a write: leave the file to it rather than race it
                self._failed('closing failed', TimeoutError(f'the writer did not finish within {timeout:g} s'))
                return
        self._take()
        self._write_until(math.inf)
        try:
            self.writer.stop()
        except Exception as exc:   # noqa: BLE001
            self._failed('closing failed', exc)


class CanLogTap:
    """Writes the frames the host sends (tx) and receives (rx) to the CAN log `path` (format by suffix,
    SUPPORTED_FORMATS) with the channel name `channel`. The file is created here: CanLogError if it cannot be.

    on_error(text) is called once, from the writing thread, at the first write error. Counters: frames_tx,
    frames_rx (handed to the log), frames_written, write_errors, frames_dropped (queue overflow),
    frames_out_of_order (older than the reorder window allows); `error` is the first error's text.
    """

    def __init__(self, path, channel=LOG_CHANNEL_SIM, on_error=None, clock=time.time):
        self.path = check_log_path(path)
        self.format = log_format(self.path)
        self.channel = channel
        self._clock = clock
        try:
            writer = can.Logger(str(self.path))
        except OSError as exc:
            raise CanLogError(f'{self.path}: cannot write the CAN log: {exc.strerror or exc}') from None
        self.frames_tx = self.frames_rx = 0
        self._rx_offset = None   # added to received timestamps (0 unless the interface's clock is not the epoch)
        self._w = _Writer(writer, self.path, on_error)
        self._finalizer = weakref.finalize(self, self._w.close)   # at interpreter exit too

    @property
    def on_error(self):
        return self._w.on_error

    @on_error.setter
    def on_error(self, callback):
        self._w.on_error = callback

    def _put(self, msg: can.Message):
        queue = self._w.queue
        if len(queue) >= MAX_QUEUED or self._w.closed:
            self._w.frames_dropped += 1
            if len(queue) >= MAX_QUEUED and not self._w.error:
                self._w._failed('dropping frames', RuntimeError(f'{MAX_QUEUED} frames waiting to be written '
                                                                '(the disk is too slow)'))
            return
        queue.append(msg)

    def tx(self, msg: can.Message):
        """A frame the host has just sent."""
        self.frames_tx += 1
        self._put(_log_copy(msg, self._clock(), False, self.channel))

    def rx(self, msg: can.Message):
        """A frame the host has received, with the bus's timestamp. An interface whose timestamps are not seconds
        since the epoch (more than MAX_CLOCK_OFFSET from the wall clock at the first frame) is moved onto the wall
        clock by that first offset, so sent and received frames stay in one time order.
        """
        self.frames_rx += 1
        now = self._clock()
        stamp = msg.timestamp
        if not stamp:
            stamp = now
        else:
            if self._rx_offset is None:
                self._rx_offset = now - stamp if abs(now - stamp) > MAX_CLOCK_OFFSET else 0.0
            stamp += self._rx_offset
        self._put(_log_copy(msg, stamp, True, self.channel))

    @property
    def closed(self) -> bool:
        return self._w.closed

    def close(self, timeout: float = 30.0):
        """Write every held frame and close the file (idempotent)."""
        self._finalizer.detach()
        self._w.close(timeout)

    @property
    def frames_written(self) -> int:
        return self._w.frames_written

    @property
    def write_errors(self) -> int:
        return self._w.write_errors

    @property
    def frames_dropped(self) -> int:
        return self._w.frames_dropped

    @property
    def frames_out_of_order(self) -> int:
        return self._w.frames_out_of_order

    @property
    def error(self) -> str:
        """The first write error, reported once ('' if none)."""
        return self._w.error


class LoggingBus:
    """A python-can Bus seen through a CanLogTap: what is sent through send() and received through recv() is
    logged; shutdown() shuts the bus down and closes the log. Every other attribute is the bus's.
    """

    def __init__(self, bus, tap: CanLogTap):
        self.bus, self.tap = bus, tap

    def send(self, msg, timeout=None):
        self.bus.send(msg, timeout)
        self.tap.tx(msg)   # only frames the bus accepted

    def recv(self, timeout=None):
        msg = self.bus.recv(timeout)
        if msg is not None:
            self.tap.rx(msg)
        return msg

    def shutdown(self):
        try:
            self.bus.shutdown()
        finally:
            self.tap.close()

    def __getattr__(self, name):
        return getattr(self.bus, name)


# ---------------------------------------------------------------------------------------------------- decoding

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
    complete is False when the log was damaged or not closed (warnings say how; what precedes it is decoded).
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


def decode_log(path, dbc=DBC_PATH) -> CanLog:
    """Read the raw CAN log `path` (.blf, .asc or candump .log) with can.LogReader and decode it with the DBC
    `dbc` (a path, or a Protocol) into a CanLog. A damaged or unclosed log decodes up to the damage, with a
    CanLogWarning (also in CanLog.warnings, complete=False). FileNotFoundError for a missing file, CanLogError for
    a file that is no log of its suffix's format.
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
    try:
        reader = can.LogReader(str(p))
    except Exception as exc:   # noqa: BLE001 - python-can raises anything from struct.error to its own errors
        raise CanLogError(f'{p}: not a readable {SUPPORTED_FORMATS[fmt]} log: {exc or type(exc).__name__}') from None
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
    more = _integrity(p, fmt, reader, out.frames_total)
    if more:
        out.complete = False
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
    by_id = proto.by_id
    cmd_names = {int(k): str(v) for k, v in proto.by_name['HostCommand'].get_signal_by_name('CMD_Code')
                 .choices.items()}
    idle_states = {i for i, s in enumerate(STATES) if s not in ('running', 'holding', 'ramping_down')}
    frames, by_id_count, channels = collections.Counter(), collections.Counter(), {}
    a = collections.defaultdict(list)   # the arrays of _ARRAYS, as lists; 'time' holds absolute timestamps
    expected = last_status_seq = sp_ref = state = None
    temperature, faults = math.nan, 0
    it = iter(reader)
    try:
        while True:
            try:
                msg = next(it)
            except StopIteration:
                break
            except Exception as exc:   # noqa: BLE001 - corrupt data: decode what precedes it
                raise _Damaged(f'{type(exc).__name__}: {exc}') from None
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
            if name == 'Feedback':
                ref = expected if expected is not None else max(last_status_seq or 0, 0)
                s = unwrap_sequence(int(sig['FB_Sequence']), ref)
                if expected is not None and s < expected:
                    out.frames_late += 1      # delayed or duplicated: its slot is already past (as the driver)
                    continue
                if expected is not None and s > expected:
                    gap = {'expected': expected, 'received': s, 'lost': s - expected, 'time': rel}
                    if state in idle_states:
                        out.jumps.append(gap)    # an idle controller started a new stream there: no loss
                    else:
                        out.gaps.append(gap)
                        out.samples_lost += s - expected
                expected = s + 1
                a['sequence'].append(s)
                a['time'].append(t)
                a['displacement'].append(sig['FB_Displacement'])
                a['force'].append(sig['FB_Force'])
                a['setpoint'].append(sig['FB_Setpoint'])
                a['temperature'].append(temperature)
                a['status'].append(faults)
            elif name == 'Setpoint':
                sp_ref = unwrap_sequence(int(sig['SP_Sequence']), sp_ref if sp_ref is not None else (expected or 0))
                a['setpoint_sequence'].append(sp_ref)
                a['setpoint_time'].append(rel)
                a['setpoint_displacement'].append(sig['SP_Displacement'])
            elif name == 'ControllerStatus':
                code, faults = int(sig['ST_State']), int(sig['ST_Faults'])
                out.faults |= faults
                last_status_seq = unwrap_sequence(int(sig['ST_LastSequence']), last_status_seq
                                                  if last_status_seq is not None else (expected or 0))
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
