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

The writer does the file: it owns the mcap Writer (chunked, zstd/lz4, message indexes and a summary) on an
unbuffered file (rawfile), flushes, turns write errors into RecordingWriteError and counts messages. The
rest is in modules of their own: schemas, channels and CDR encoding (channels), the gap check of the rig's
sample streams (gapcheck, gaps), metadata names and values (metadata), rosbag2's bag info (bagmeta).

- Crash safety: each MCAP record reaches the OS in one write, and the chunk in progress is closed at least
  every ``flush_interval_s`` of log time, so a SIGKILL loses at most that much; ``rubber_rig.recording.recover``
  rebuilds the summary of such a file.
- Loss is never silent: messages that could not be written are counted by reason, sequence gaps of the rig's
  sample streams are counted, and both go into a ``rubber_rig.close`` metadata record when the file is closed.
"""
import errno as errno_mod
import time
from datetime import datetime, timezone
from pathlib import Path

from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from rubber_rig import __version__

from . import bagmeta
from .channels import ChannelTable
from .errors import RecordingError, RecordingWriteError
from .gapcheck import GapCheck
from .gaps import LossLedger
from .metadata import CLOSE_METADATA_NAME, METADATA_NAME, SEQUENCE_SOURCE_KEY, bookkeeping_text, encode_metadata
from .msgdefs import MessageDefinitionError, normalize_type, type_of
from .rawfile import UnbufferedFile

COMPRESSION = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4, 'none': CompressionType.NONE,
               '': CompressionType.NONE}


class RecordingWriter:
    """Write ROS 2 messages (CDR bytes, rosidl messages or plain dicts) to one MCAP file.

    ``metadata`` becomes the ``rubber_rig`` metadata record (specimen, temperature, model, parameters,
    test program, rig configuration, ...); software version and start time are added.
    """

    def __init__(self, path, metadata: dict = None, *, compression: str = 'zstd',
                 chunk_size: int = 1 << 20, flush_interval_s: float = 1.0, gaps: LossLedger = None,
                 overwrite: bool = False, bookkeeping_topic: str | None = None, clock_ns=time.time_ns):
        self.path = Path(path)
        self._clock_ns = clock_ns          # ns since the epoch: start, close and default log times (a scenario's)
        self.bookkeeping_topic = bookkeeping_topic   # where close() also writes the records as a message
        if compression not in COMPRESSION:
            raise RecordingError(f'unknown compression {compression!r}; use zstd, lz4 or none')
        try:
            self._file = UnbufferedFile(self.path, overwrite)
        except OSError as exc:
            raise RecordingWriteError(f'cannot create recording {self.path}: {exc.strerror}',
                                      exc.errno) from None
        self._mcap = McapWriter(self._file, chunk_size=chunk_size, compression=COMPRESSION[compression])
        self._flush_interval_ns = int(flush_interval_s * 1e9) if flush_interval_s else 0
        self._channels = ChannelTable(self._mcap, self._guard)
        self._gap_check = GapCheck(self.path, gaps)
        self.messages_written = 0
        self.messages_flushed = 0          # messages in complete chunks handed to the OS
        self.last_flushed_log_time_ns = None
        self.messages_by_topic = {}
        self.dropped = {}                  # reason -> count of messages not written
        self.first_log_time_ns = None
        self.last_log_time_ns = None
        self._last_flush_ns = None
        self._pending = 0                  # uncompressed bytes in the chunk in progress
        self.failure = None                # the OSError that stopped this writer, if any
        self.closed = False
        start_time_ns = self._clock_ns()
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

    @property
    def gaps(self) -> LossLedger:
        """The loss ledger (shared by the files of a split recording)."""
        return self._gap_check.gaps

    @property
    def samples_written(self) -> int:
        """Samples of sample-stream messages (RigSampleBatch, RigSample) written."""
        return self._gap_check.samples_written

    @property
    def samples_flushed(self) -> int:
        """Samples of sample-stream messages in complete chunks handed to the OS."""
        return self._gap_check.samples_flushed

    @property
    def samples_lost_unwritten(self) -> int:
        """Samples of the chunk a write error lost."""
        return self._gap_check.samples_lost_unwritten

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
            self._gap_check.chunk_lost()
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
        return self._channels.add(topic, msg_type, qos, topic_type_hash, sequence_source)

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
                data = self._channels.encode(msg_type, msg)
            except Exception as exc:  # the encoder raises many types; name the message instead
                self.count_dropped('encode_error')
                raise RecordingError(f'cannot encode a {msg_type} for {topic}: {exc}') from None
            decoded = msg
        if log_time_ns is None:
            log_time_ns = self._clock_ns()
        if publish_time_ns is None:
            publish_time_ns = log_time_ns
        sequence = int(self._channels.sequence(channel_id, sequence)) & 0xFFFFFFFF
        before = self._file.tell()
        try:
            self._guard(self._mcap.add_message, channel_id, int(log_time_ns), data,
                        int(publish_time_ns), sequence)
        except RecordingWriteError:
            self.count_dropped('write_error')
            raise
        self._pending += len(data) + 31
        self.messages_written += 1
        self.messages_by_topic[topic] = self.messages_by_topic.get(topic, 0) + 1
        if self.first_log_time_ns is None:
            self.first_log_time_ns = self._last_flush_ns = log_time_ns
        self.last_log_time_ns = log_time_ns
        # the ledger sees the publication sequence as every reader of the file will: the stored one, if the channel
        # stores publication sequence numbers
        publication_sequence = sequence if self._channels.publication_sequenced(channel_id) else None
        if not self._gap_check.observe(topic, msg_type, self._channels.schema(msg_type), data, decoded,
                                       log_time_ns, publication_sequence):
            self.count_dropped('undecodable_for_gap_check')
        if self._file.tell() != before:    # mcap closed a full chunk (with this message) just now
            self._pending = 0
            self._mark_flushed()
        if self._flush_interval_ns and log_time_ns - self._last_flush_ns >= self._flush_interval_ns:
            self.flush()

    def _mark_flushed(self):
        self.messages_flushed = self.messages_written
        self._gap_check.flushed()
        self.last_flushed_log_time_ns = self.last_log_time_ns

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

    def part(self) -> dict:
        """Samples of the sample stream in this file and the first and last sample's sequence (GapCheck.part)."""
        return self._gap_check.part()

    def loss_report(self) -> dict:
        return {
            'messages_written': self.messages_written,
            'messages_by_topic': dict(self.messages_by_topic),
            'messages_dropped': sum(self.dropped.values()),
            'dropped_by_reason': dict(self.dropped),
            **self._gap_check.report(),
        }

    def bag_info(self) -> dict:
        """rosbag2's bag metadata of this file alone."""
        first = self.first_log_time_ns or 0
        files = [{'path': self.path.name, 'start_ns': first, 'end_ns': self.last_log_time_ns or first,
                  'count': self.messages_written}]
        return bagmeta.make_bag_info(files, self._channels.bag_topics(self.messages_by_topic))

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
                values = dict(report, end_time_ns=self._clock_ns(), clean_close=True, **(extra or {}))
                if self.bookkeeping_topic:
                    self._write_bookkeeping(values)
                self._guard(self._mcap.add_metadata, CLOSE_METADATA_NAME, encode_metadata(values))
                self._guard(self._mcap.add_metadata, 'rosbag2',
                            {'serialized_metadata': bagmeta.dump(self.bag_info())})
                self._guard(self._mcap.finish)
                self._guard(self._file.fsync)
        finally:
            self._file.close()
        return report

    def _write_bookkeeping(self, close_values: dict) -> None:
        """The two metadata records, also as one message (std_msgs/String, JSON, on `bookkeeping_topic`: the recorder
        node's ``<namespace>/recording_info``, where it latches them too): MCAP metadata records do not survive a
        conversion by rosbag2-compatible tools (rosbags: MCAP -> sqlite3 -> MCAP), messages do. Its counts are
        those of the other messages (the close record's).
        """
        self.write_message(self.bookkeeping_topic, 'std_msgs/msg/String',
                           {'data': bookkeeping_text(self.metadata, close_values)})

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# the metadata names and encode_metadata were defined here before the split: still importable from here
__all__ = ['RecordingWriter', 'COMPRESSION', 'METADATA_NAME', 'CLOSE_METADATA_NAME', 'SEQUENCE_SOURCE_KEY',
           'encode_metadata']
