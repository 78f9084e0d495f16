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

"""Recorder: a recording session over RecordingWriter files (ROS-free; the recorder node wires it up).

- start / stop / split, automatic splits by size and by duration. A split happens between two
  messages, so every message lands in exactly one file (none lost, none duplicated).
- Sequence gaps are tracked across the files of one recording (a gap across a split is still seen), by the loss
  ledger that ``rubber-rig info`` and ``recover`` use too (gaps.LossLedger).
- A write error (disk full, file too large) stops the recording cleanly: the file keeps everything up
  to its last complete chunk, the error is kept in ``error`` and messages that arrive afterwards are
  counted as not recorded (never silently lost): the samples of the chunk that could not be written and
  of every sample batch that arrives after the error are added to ``samples_lost_total``.
- ``start`` creates the directory and the first file and writes its header before it returns, so a
  recording that started is known writable; a directory that cannot be created or written raises
  RecordingWriteError naming the path (and keeps it in ``error``).
- The files of a split recording name their parts (parts.py): each file's ``rubber_rig`` record carries the
  recording's id (``recording_id``, one per start), its ``part_index``, the samples written to the parts before it
  (``samples_before``) and the last sample of the part before (``previous_last_sample``); its close record adds
  what it holds (``part_samples``, ``first_sample``, ``last_sample``) and whether the recording continued in a next
  part (``next_part``) or ended with it (``final_part``). ``metadata.yaml`` lists every part in its custom_data.
  From these, ``rubber-rig info`` and ``recover`` tell a missing part, and how many samples it held.
- Snapshot: with ``snapshot_duration_s`` > 0 the last N seconds (log time) are kept in memory, and
  ``snapshot()`` writes them to their own file, recording or not (like rosbag2's snapshot mode).
"""
import json
import time
import uuid
from collections import deque
from datetime import datetime, timezone
from pathlib import Path

from mcap.records import Schema

from .bagmeta import write_bag_metadata
from .errors import RecordingError, RecordingWriteError
from .gaps import LossLedger, sequence_span
from .mcapio import Decoders
from .msgdefs import full_definition, normalize_type
from .parts import PARTS_KEY, RECORDING_ID_KEY
from .writer import RecordingWriter


def _stamp(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, tz=timezone.utc).strftime('%Y%m%d-%H%M%S')


def _unique(base: Path, suffix: str = '') -> Path:
    """base+suffix, or base-1+suffix, base-2+suffix, ... whichever does not exist yet."""
    candidate, i = base.with_name(base.name + suffix), 0
    while candidate.exists():
        i += 1
        candidate = base.with_name(f'{base.name}-{i}{suffix}')
    return candidate


class Recorder:
    def __init__(self, output_dir, *, metadata: dict = None, compression: str = 'zstd',
                 split_size_bytes: int = 0, split_duration_s: float = 0.0, chunk_size: int = 1 << 20,
                 flush_interval_s: float = 1.0, snapshot_duration_s: float = 0.0, bookkeeping_topic: str = None):
        self.output_dir = Path(output_dir)
        self.bookkeeping_topic = bookkeeping_topic   # each file's records also as a message there (writer)
        self.metadata = dict(metadata or {})
        self.compression = compression
        self.split_size_bytes = int(split_size_bytes)
        self.split_duration_ns = int(split_duration_s * 1e9)
        # a chunk must be well below the split size, or the size check would only see whole chunks
        self.chunk_size = min(chunk_size, max(4096, self.split_size_bytes // 8)) \
            if self.split_size_bytes else chunk_size
        self.flush_interval_s = flush_interval_s
        self.snapshot_duration_ns = int(snapshot_duration_s * 1e9)
        self._buffer = deque()
        self._qos = {}                       # topic -> offered QoS (list of dicts or YAML)
        self.writer = None
        self.gaps = LossLedger()             # the loss ledger of the recording, across its files
        self.files = []                      # files of the current/last recording, in order
        self._summaries = {}                 # closed file -> bagmeta.file_summary, for metadata.yaml
        self.reports = []                    # loss report of each closed file
        self.error = None                    # RecordingWriteError that stopped the recording
        self.not_recorded_after_error = 0
        self.samples_not_recorded = 0        # samples of batches that arrived after a write error
        self.samples_unwritten = 0           # samples in chunks a write error lost
        self._decoders = None
        self.warnings = []
        self.messages_written = 0
        self.dropped = 0
        self._base = None
        self._index = 0
        self.recording_id = ''               # one per start(): every part of the recording carries it
        self.parts = []                      # per closed part: index, file, samples, first/last sample, closed
        self._samples_before = 0             # samples of the sample stream in the parts closed so far
        self._previous_last = None           # sequence of the last sample of the part before
        self.refused: dict[str, int] = {}    # topic -> messages refused unrecorded (a forged signature: refuse())

    # -- state -------------------------------------------------------------------------------
    @property
    def recording(self) -> bool:
        return self.writer is not None

    @property
    def current_file(self):
        return self.writer.path if self.writer is not None else None

    @property
    def samples_lost_total(self) -> int:
        """Every sample known lost: the ledger's (sequence gaps of the sample stream that are real loss: what
        ``rubber-rig info`` counts in the files), and samples received but not written (a write error's lost
        chunk, batches after the error).
        """
        return self.gaps.samples_lost + self.samples_not_recorded + self.samples_unwritten

    def set_qos(self, topic: str, qos) -> None:
        self._qos[topic] = qos

    def stats(self) -> dict:
        w = self.writer
        return {
            'recording': self.recording,
            'file': str(w.path) if w else '',
            'files': len(self.files),
            'messages_written': self.messages_written + (w.messages_written if w else 0),
            'messages_dropped': self.dropped + (sum(w.dropped.values()) if w else 0)
            + self.not_recorded_after_error,
            'messages_flushed_current_file': w.messages_flushed if w else 0,
            'not_recorded_after_error': self.not_recorded_after_error,
            'samples_not_recorded': self.samples_not_recorded + self.samples_unwritten,
            'samples_lost_total': self.samples_lost_total,
            'bytes_current_file': w.size_estimate if w else 0,
            'error': str(self.error) if self.error else '',
            'warnings': '; '.join(self.warnings),
            'messages_refused': sum(self.refused.values()),
            **self.gaps.summary(),
        }

    def refuse(self, topic: str) -> None:
        """Count a message on `topic` that was refused (not written: its signature did not verify, so it is not the
        data it claims to be). The count goes into /diagnostics and each file's close record (messages_refused).
        """
        self.refused[topic] = self.refused.get(topic, 0) + 1

    # -- control -----------------------------------------------------------------------------
    def start(self, path=None) -> Path:
        """Start a new recording: ``path`` names its directory (default: output_dir/rubber_rig_<utc>).
        Files inside are <name>_0.mcap, <name>_1.mcap, ... as rosbag2 names split files.
        """
        if self.recording:
            return self.writer.path
        now = time.time_ns()
        base = Path(path) if path else _unique(self.output_dir / f'rubber_rig_{_stamp(now)}')
        if base.suffix == '.mcap':
            base = base.with_suffix('')
        try:
            base.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            self.error = RecordingWriteError(f'cannot create recording directory {base.absolute()}: '
                                             f'{exc.strerror}', exc.errno)
            raise self.error from None
        self._base, self._index = base, 0
        self.recording_id, self.parts = uuid.uuid4().hex, []
        self._samples_before, self._previous_last = 0, None
        self.gaps = LossLedger()
        self.files, self.reports, self._summaries = [], [], {}
        self.error, self.not_recorded_after_error = None, 0
        self.samples_not_recorded = self.samples_unwritten = 0
        self.messages_written = self.dropped = 0
        try:
            self._open()
        except RecordingError as exc:        # read-only directory, disk full at the header, ...
            self.error = exc
            raise
        return self.writer.path

    def _open(self):
        path = (self._base / f'{self._base.name}_{self._index}.mcap').absolute()
        self._index += 1
        metadata = dict(self.metadata, recording=self._base.name, file_index=str(self._index - 1),
                        recording_id=self.recording_id, part_index=self._index - 1,
                        samples_before=self._samples_before, previous_last_sample=self._previous_last)
        self.writer = RecordingWriter(path, metadata, compression=self.compression,
                                      chunk_size=self.chunk_size, flush_interval_s=self.flush_interval_s,
                                      gaps=self.gaps, bookkeeping_topic=self.bookkeeping_topic)
        self.files.append(path)

    def _close_writer(self, continues: bool = False):
        """Close the current file; ``continues``: the recording goes on in the next part (a split)."""
        w, self.writer = self.writer, None
        if w is None:
            return
        part = w.part()
        index = self._index - 1
        next_part = f'{self._base.name}_{self._index}.mcap' if continues else ''
        extra = dict(part, recording_id=self.recording_id, part_index=index, next_part=next_part,
                     final_part=not continues, messages_refused=sum(self.refused.values()),
                     messages_refused_by_topic=', '.join(f'{k}: {n}' for k, n in sorted(self.refused.items())))
        try:
            self.reports.append(w.close(extra))
        except RecordingWriteError as exc:
            self.error = self.error or exc
        self.parts.append(dict(part, index=index, file=w.path.name, closed=w.failure is None,
                               samples_before=self._samples_before, next_part=next_part))
        self._samples_before += part['part_samples']
        if part['last_sample'] is not None:
            self._previous_last = part['last_sample']
        self.messages_written += w.messages_written
        self.dropped += sum(w.dropped.values())
        self.samples_unwritten += w.samples_lost_unwritten
        try:                                 # the bag so far, for rosbag2 / rosbags readers, with every part
            write_bag_metadata(self._base, self.files, self._summaries,
                               {RECORDING_ID_KEY: self.recording_id, PARTS_KEY: json.dumps(self.parts)})
        except (OSError, RecordingError) as exc:   # the MCAP files are complete; only the index is missing
            self.warnings.append(f'metadata.yaml of {self._base} not written: {exc}')

    def stop(self) -> list:
        """Stop recording; returns the files written."""
        self._close_writer()
        return list(self.files)

    def split(self) -> Path:
        """Close the current file and continue in the next one."""
        if not self.recording:
            raise RecordingError('not recording: nothing to split')
        self._close_writer(continues=True)
        if self.error is None:
            self._open()
        return self.current_file

    def _fail(self, exc: RecordingWriteError):
        self.error = exc
        self._close_writer()                 # only closes the fd: the writer knows it failed

    # -- data --------------------------------------------------------------------------------
    def write(self, topic: str, msg_type: str, msg, log_time_ns: int = None, publish_time_ns: int = None,
              sequence: int = None) -> bool:
        """Record one message (CDR bytes, rosidl message or dict). Returns True if it was written."""
        if log_time_ns is None:
            log_time_ns = time.time_ns()
        if self.snapshot_duration_ns:
            self._remember(topic, msg_type, msg, log_time_ns, publish_time_ns, sequence)
        w = self.writer
        if w is None:
            if self.error is not None:
                self.not_recorded_after_error += 1
                self.samples_not_recorded += self._samples_in(topic, msg_type, msg)
            return False
        try:
            if w.messages_written and (
                    (self.split_size_bytes and w.size_estimate >= self.split_size_bytes)
                    or (self.split_duration_ns
                        and log_time_ns - w.first_log_time_ns >= self.split_duration_ns)):
                self.split()
                w = self.writer
            w.write_message(topic, msg_type, msg, log_time_ns, publish_time_ns, sequence,
                            qos=self._qos.get(topic))
            return True
        except RecordingWriteError as exc:
            self._fail(exc)
            self.samples_not_recorded += self._samples_in(topic, msg_type, msg)
            return False
        except (RecordingError, ValueError):
            return False                     # counted by the writer (unknown type / encode error)

    def _samples_in(self, topic, msg_type, msg) -> int:
        """Samples carried by a message that could not be written (0 for other than sample-stream types)."""
        try:
            msg_type = normalize_type(msg_type)
            if isinstance(msg, (bytes, bytearray, memoryview)):
                if self._decoders is None:
                    self._decoders = Decoders('(not recorded)', lazy_fallback=True)
                schema = Schema(0, full_definition(msg_type).encode(), 'ros2msg', msg_type)
                msg = self._decoders.decode(schema, bytes(msg), topic)
            span = sequence_span(msg_type, msg)
        except Exception:  # noqa: BLE001 - not a sample stream, or undecodable: no samples to count
            return 0
        return span[1] if span else 0

    def flush(self, fsync: bool = False) -> None:
        if self.writer is not None:
            try:
                self.writer.flush(fsync)
            except RecordingWriteError as exc:
                self._fail(exc)

    # -- snapshot ----------------------------------------------------------------------------
    def _remember(self, topic, msg_type, msg, log_time_ns, publish_time_ns, sequence):
        buf = self._buffer
        buf.append((topic, msg_type, msg, log_time_ns, publish_time_ns, sequence))
        horizon = log_time_ns - self.snapshot_duration_ns
        while buf and buf[0][3] < horizon:
            buf.popleft()

    def snapshot(self, path=None) -> Path:
        """Write the buffered last ``snapshot_duration_s`` seconds to a file of their own."""
        if not self.snapshot_duration_ns:
            raise RecordingError('snapshot_duration_s is 0: no snapshot buffer is kept')
        now = time.time_ns()
        path = Path(path) if path else _unique(self.output_dir / f'snapshot_{_stamp(now)}', '.mcap')
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise RecordingWriteError(f'cannot create {path.parent}: {exc.strerror}', exc.errno) from None
        items = list(self._buffer)
        metadata = dict(self.metadata, snapshot='true',
                        snapshot_duration_s=str(self.snapshot_duration_ns / 1e9))
        writer = RecordingWriter(path, metadata, compression=self.compression,
                                 chunk_size=self.chunk_size, flush_interval_s=0,
                                 bookkeeping_topic=self.bookkeeping_topic)
        try:
            for topic, msg_type, msg, log_ns, pub_ns, seq in items:
                try:
                    writer.write_message(topic, msg_type, msg, log_ns, pub_ns, seq,
                                         qos=self._qos.get(topic))
                except RecordingWriteError:
                    raise
                except (RecordingError, ValueError):
                    pass                     # counted in the snapshot's close record
        finally:
            writer.close()
        return path
