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
reads such a log back (:mod:`.canlog_reader`).

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
import heapq
import itertools
import logging
import math
import os
import threading
import time
import weakref
from pathlib import Path

import can

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
    """A CAN log was read only in part: a truncated, unclosed or corrupt BLF is decoded up to the damage; in a
    text log (.asc, .log) the unreadable lines are skipped (named by number, with the reason) and the frames
    before and after them are decoded.
    """


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
