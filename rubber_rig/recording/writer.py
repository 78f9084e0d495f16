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

"""RecordingWriter: one MCAP file in the ros2 profile, as rosbag2's MCAP storage writes it (ROS-free).

- Schemas: ``ros2msg`` with the full concatenated definition (msgdefs.full_definition); channels:
  ``cdr`` with ``offered_qos_profiles`` and ``topic_type_hash`` metadata; chunked, zstd/lz4, with
  message indexes and a summary (mcap's Writer does the format).
- Crash safety: the file is written unbuffered (each MCAP record reaches the OS in one write), and the
  chunk in progress is closed at least every ``flush_interval_s`` of log time, so a SIGKILL loses at
  most that much; ``rubber_rig.recording.recover`` rebuilds the summary of such a file.
- Loss is never silent: messages that could not be written are counted by reason, sequence gaps of the
  rig's sample streams are counted (gaps.GapTracker), and both go into a ``rubber_rig.close`` metadata
  record when the file is closed.
"""
import errno as errno_mod
import json
import os
import time
from datetime import datetime, timezone
from pathlib import Path

from mcap.records import Schema
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from rubber_rig import __version__

from . import bagmeta, mcap_compat
from .errors import RecordingError, RecordingWriteError
from .gaps import SEQUENCED_TYPES, GapTracker, sequence_span
from .mcapio import Decoders
from .msgdefs import MessageDefinitionError, full_definition, normalize_type, type_hash, type_of
from .qos import offered_qos_yaml

METADATA_NAME = 'rubber_rig'           # self-description record written at the start of every file
# channel metadata key: 'publication' when the MCAP message sequence is the DDS publication sequence number
# (gaps in it are messages lost in transport), 'writer' when the writer numbered the messages itself
SEQUENCE_SOURCE_KEY = 'rubber_rig.sequence'
CLOSE_METADATA_NAME = 'rubber_rig.close'  # loss accounting written when a file is closed
COMPRESSION = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4, 'none': CompressionType.NONE,
               '': CompressionType.NONE}


def encode_metadata(values: dict) -> dict:
    """MCAP metadata values are strings: keep strings, JSON-encode the rest and remember which."""
    out, json_keys = {}, []
    for key, value in (values or {}).items():
        if isinstance(value, str):
            out[str(key)] = value
        else:
            out[str(key)] = json.dumps(_plain(value), sort_keys=True)
            json_keys.append(str(key))
    if json_keys:
        out['_json_keys'] = ','.join(json_keys)
    return out


def _plain(value):
    """Rosidl messages, numpy arrays and array.array -> dicts, lists and Python numbers, the forms the
    dynamic CDR encoder (and JSON) accept; rosidl's byte fields (bytes objects) become ints/bytes.
    """
    fields = getattr(value, 'get_fields_and_field_types', None)
    if fields is not None:
        out = {}
        for name, ftype in fields().items():
            v = getattr(value, name)
            if ftype == 'octet' and isinstance(v, (bytes, bytearray)):
                v = v[0] if v else 0
            elif ftype.startswith(('sequence<octet', 'octet[')) and isinstance(v, (list, tuple)):
                v = b''.join(v)
            out[name] = _plain(v)
        return out
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    if hasattr(value, 'tolist'):
        return value.tolist()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


class _UnbufferedFile:
    """Write-only file whose every write goes straight to the OS (no Python-side buffer to lose)."""

    def __init__(self, path: Path, overwrite: bool):
        flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL)
        self._fd = os.open(path, flags, 0o644)
        self._pos = 0

    def write(self, data) -> int:
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            if n <= 0:
                raise OSError(errno_mod.ENOSPC, 'no space left on device')
            self._pos += n
            view = view[n:]
        return len(data)

    def tell(self) -> int:
        return self._pos

    def flush(self):
        pass

    def fsync(self):
        os.fsync(self._fd)

    def close(self):
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


class RecordingWriter:
    """Write ROS 2 messages (CDR bytes, rosidl messages or plain dicts) to one MCAP file.

    ``metadata`` becomes the ``rubber_rig`` metadata record (specimen, temperature, model, parameters,
    test program, rig configuration, ...); software version and start time are added.
    """

    def __init__(self, path, metadata: dict = None, *, compression: str = 'zstd',
                 chunk_size: int = 1 << 20, flush_interval_s: float = 1.0, gaps: GapTracker = None,
                 overwrite: bool = False):
        self.path = Path(path)
        if compression not in COMPRESSION:
            raise RecordingError(f'unknown compression {compression!r}; use zstd, lz4 or none')
        try:
            self._file = _UnbufferedFile(self.path, overwrite)
        except OSError as exc:
            raise RecordingWriteError(f'cannot create recording {self.path}: {exc.strerror}',
                                      exc.errno) from None
        self._mcap = McapWriter(self._file, chunk_size=chunk_size, compression=COMPRESSION[compression])
        self._flush_interval_ns = int(flush_interval_s * 1e9) if flush_interval_s else 0
        self._schemas, self._channels, self._sequences = {}, {}, {}
        self._channel_qos, self._channel_hash = {}, {}
        self._schema_records = {}          # msg_type -> its Schema record (for the gap check's decoder)
        self._encoders = {}
        # numpy decoder for the gap check (10 kHz), mcap_ros2's only if it fails (e.g. big-endian CDR)
        self._decoders = Decoders(self.path, lazy_fallback=True)
        self.gaps = gaps if gaps is not None else GapTracker()
        # the tracker may carry on from earlier files: this file reports what it added since it opened
        self._gaps_at_open = self.gaps.summary()
        self._events_at_open = len(self.gaps.events)
        self.messages_written = 0
        self.messages_flushed = 0          # messages in complete chunks handed to the OS
        self.samples_written = 0           # samples of sequenced messages (RigSampleBatch, ...) written
        self.samples_flushed = 0           # ... of them in complete chunks handed to the OS
        self.samples_lost_unwritten = 0    # samples of the chunk a write error lost
        self.last_flushed_log_time_ns = None
        self.messages_by_topic = {}
        self.dropped = {}                  # reason -> count of messages not written
        self.first_log_time_ns = None
        self.last_log_time_ns = None
        self._last_flush_ns = None
        self._pending = 0                  # uncompressed bytes in the chunk in progress
        self.failure = None                # the OSError that stopped this writer, if any
        self.closed = False
        start_time_ns = time.time_ns()
        self.metadata = dict(metadata or {})
        self.metadata.setdefault('software_version', __version__)
        self.metadata.setdefault('start_time', datetime.fromtimestamp(
            start_time_ns / 1e9, tz=timezone.utc).isoformat())
        self.metadata.setdefault('start_time_ns', str(start_time_ns))
        try:
            self._guard(self._mcap.start, 'ros2', f'rubber_rig {__version__}')
            self._guard(self._mcap.add_metadata, METADATA_NAME, encode_metadata(self.metadata))
        except RecordingWriteError:
            self._file.close()
            self.closed = True
            raise

    # -- state -------------------------------------------------------------------------------
    @property
    def size_estimate(self) -> int:
        """Bytes on disk plus the (uncompressed) chunk in progress: an upper bound for splitting."""
        return self._file.tell() + self._pending

    def _guard(self, fn, *args, **kwargs):
        if self.failure is not None:
            raise RecordingWriteError(f'recording {self.path} stopped after a write error: '
                                      f'{self.failure.strerror}', self.failure.errno)
        try:
            return fn(*args, **kwargs)
        except OSError as exc:
            self.failure = exc
            # messages of the chunk that could not be written are lost too: say how many
            if self.messages_written > self.messages_flushed:
                self.count_dropped('lost_in_unwritten_chunk', self.messages_written - self.messages_flushed)
            self.samples_lost_unwritten = self.samples_written - self.samples_flushed
            what = {errno_mod.ENOSPC: 'disk full', errno_mod.EFBIG: 'file too large',
                    errno_mod.EDQUOT: 'disk quota exceeded'}.get(exc.errno, exc.strerror)
            raise RecordingWriteError(f'writing {self.path} failed ({what}); the file is kept up to '
                                      'its last complete chunk, `rubber-rig recover` makes it readable',
                                      exc.errno) from None

    def count_dropped(self, reason: str, n: int = 1):
        self.dropped[reason] = self.dropped.get(reason, 0) + n

    # -- channels ----------------------------------------------------------------------------
    def add_channel(self, topic: str, msg_type: str, qos=None, topic_type_hash: str = None,
                    sequence_source: str = 'writer') -> int:
        """Register a topic (done implicitly by write_message). ``qos``: offered profiles as a list
        of dicts (qos.qos_entry keywords) or the rosbag2 YAML string.
        """
        msg_type = normalize_type(msg_type)
        known = self._channels.get(topic)
        if known is not None:
            if known[1] != msg_type:
                raise RecordingError(f'topic {topic} already recorded as {known[1]}, got {msg_type}')
            return known[0]
        schema_id = self._schemas.get(msg_type)
        if schema_id is None:
            text = full_definition(msg_type).encode()
            schema_id = self._guard(self._mcap.register_schema, msg_type, 'ros2msg', text)
            self._schemas[msg_type] = schema_id
            self._schema_records[msg_type] = Schema(schema_id, text, 'ros2msg', msg_type)
        metadata = {'offered_qos_profiles': offered_qos_yaml(qos or []),
                    'topic_type_hash': topic_type_hash if topic_type_hash is not None
                    else type_hash(msg_type), SEQUENCE_SOURCE_KEY: sequence_source}
        self._channel_qos[topic] = metadata['offered_qos_profiles']
        self._channel_hash[topic] = metadata['topic_type_hash']
        channel_id = self._guard(self._mcap.register_channel, topic, 'cdr', schema_id, metadata)
        self._channels[topic] = (channel_id, msg_type)
        self._sequences[channel_id] = 0
        return channel_id

    def _encoder(self, msg_type):
        fn = self._encoders.get(msg_type)
        if fn is None:
            fn = mcap_compat.encoder(msg_type, full_definition(msg_type))
            self._encoders[msg_type] = fn
        return fn

    # -- messages ----------------------------------------------------------------------------
    def write_message(self, topic: str, msg_type: str, msg, log_time_ns: int = None,
                      publish_time_ns: int = None, sequence: int = None, qos=None) -> None:
        """Write one message. ``msg``: CDR bytes (as rclpy's raw subscriptions give them), a
        rosidl-generated message or a dict of fields. Times in ns since the epoch (default: now).
        """
        if msg_type is None:
            msg_type = type_of(msg)
        try:
            msg_type = normalize_type(msg_type)
            channel_id = self.add_channel(topic, msg_type, qos,
                                          sequence_source='writer' if sequence is None else 'publication')
        except MessageDefinitionError:
            self.count_dropped('unknown_type')
            raise
        except RecordingWriteError:
            self.count_dropped('write_error')
            raise
        except RecordingError:
            self.count_dropped('type_conflict')
            raise
        if isinstance(msg, (bytes, bytearray, memoryview)):
            data = bytes(msg)
            decoded = None
        else:
            try:
                data = self._encoder(msg_type)(_plain(msg))
            except Exception as exc:  # the encoder raises many types; name the message instead
                self.count_dropped('encode_error')
                raise RecordingError(f'cannot encode a {msg_type} for {topic}: {exc}') from None
            decoded = msg
        if log_time_ns is None:
            log_time_ns = time.time_ns()
        if publish_time_ns is None:
            publish_time_ns = log_time_ns
        publication_sequence = sequence
        if sequence is None:
            sequence = self._sequences[channel_id] + 1
        self._sequences[channel_id] = sequence
        before = self._file.tell()
        try:
            self._guard(self._mcap.add_message, channel_id, int(log_time_ns), data,
                        int(publish_time_ns), int(sequence) & 0xFFFFFFFF)
        except RecordingWriteError:
            self.count_dropped('write_error')
            raise
        self._pending += len(data) + 31
        self.messages_written += 1
        self.messages_by_topic[topic] = self.messages_by_topic.get(topic, 0) + 1
        if self.first_log_time_ns is None:
            self.first_log_time_ns = self._last_flush_ns = log_time_ns
        self.last_log_time_ns = log_time_ns
        if msg_type in SEQUENCED_TYPES:
            self._track(topic, msg_type, data, decoded, log_time_ns, publication_sequence)
        if self._file.tell() != before:    # mcap closed a full chunk (with this message) just now
            self._pending = 0
            self._mark_flushed()
        if self._flush_interval_ns and log_time_ns - self._last_flush_ns >= self._flush_interval_ns:
            self.flush()

    def _mark_flushed(self):
        self.messages_flushed = self.messages_written
        self.samples_flushed = self.samples_written
        self.last_flushed_log_time_ns = self.last_log_time_ns

    def _track(self, topic, msg_type, data, decoded, log_time_ns, publication_sequence=None):
        if decoded is None:
            try:
                decoded = self._decoders.decode(self._schema_records[msg_type], data, topic)
            except Exception:  # undecodable bytes are recorded anyway; count them
                self.count_dropped('undecodable_for_gap_check')
                return
        event = self.gaps.observe_message(topic, msg_type, decoded, log_time_ns,
                                          publication_sequence & 0xFFFFFFFF
                                          if publication_sequence is not None else None)
        span = sequence_span(msg_type, decoded)
        if span is not None:
            self.samples_written += span[1]
        return event

    def add_metadata(self, name: str, values: dict) -> None:
        self._guard(self._mcap.add_metadata, name, encode_metadata(values))

    def flush(self, fsync: bool = False) -> None:
        """Close the chunk in progress and hand it to the OS (survives SIGKILL; fsync: power loss)."""
        self._guard(self._mcap.flush)
        self._pending = 0
        self._mark_flushed()
        self._last_flush_ns = self.last_log_time_ns or 0
        if fsync:
            self._guard(self._file.fsync)

    def loss_report(self) -> dict:
        now, at_open = self.gaps.summary(), self._gaps_at_open
        added = {key: now[key] - at_open[key] for key in
                 ('sequence_gaps', 'samples_lost', 'sequence_restarts', 'sequence_jumps', 'samples_skipped')}
        return {
            'messages_written': self.messages_written,
            'messages_by_topic': dict(self.messages_by_topic),
            'messages_dropped': sum(self.dropped.values()),
            'dropped_by_reason': dict(self.dropped),
            **added,                                            # sequence jumps (between programs) are not loss
            'samples_lost_unwritten': self.samples_lost_unwritten,
            'gap_events': self.gaps.events[self._events_at_open:],
            'total_sequence_gaps': now['sequence_gaps'],
            'total_samples_lost': now['samples_lost'],
        }

    def bag_info(self) -> dict:
        """rosbag2's bag metadata of this file alone."""
        first = self.first_log_time_ns or 0
        files = [{'path': self.path.name, 'start_ns': first, 'end_ns': self.last_log_time_ns or first,
                  'count': self.messages_written}]
        topics = [{'name': topic, 'type': msg_type, 'qos': self._channel_qos.get(topic, ''),
                   'hash': self._channel_hash.get(topic, ''), 'count': self.messages_by_topic.get(topic, 0)}
                  for topic, (_, msg_type) in self._channels.items()]
        return bagmeta.make_bag_info(files, topics)

    def close(self, extra: dict = None) -> dict:
        """Write the loss report and the summary; returns the report. After a write error the file
        is only closed (it ends at its last complete record; recover rebuilds the summary).
        """
        if self.closed:
            return self.loss_report()
        self.closed = True
        report = self.loss_report()
        try:
            if self.failure is None:
                values = dict(report, end_time_ns=time.time_ns(), clean_close=True, **(extra or {}))
                self._guard(self._mcap.add_metadata, CLOSE_METADATA_NAME, encode_metadata(values))
                self._guard(self._mcap.add_metadata, 'rosbag2',
                            {'serialized_metadata': bagmeta.dump(self.bag_info())})
                self._guard(self._mcap.finish)
                self._guard(self._file.fsync)
        finally:
            self._file.close()
        return report

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
