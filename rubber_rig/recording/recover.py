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

"""Rebuild an MCAP file whose writer was killed (SIGKILL, power cut, full disk).

Such a file has a header and complete chunks, maybe a partial last record, but no summary or footer.
Everything readable is copied into a new, complete file (schemas, channels with their metadata, every
message with its times and sequence, metadata records, attachments); the loss accounting that the
writer could not write is recomputed from the data (sequence gaps) and stored in a
``rubber_rig.recovered`` metadata record. Like ``mcap recover`` of the Go CLI, but in Python.
"""
import os
from dataclasses import dataclass
from pathlib import Path

from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from .bagmeta import METADATA_FILE, write_bag_metadata
from .errors import RecordingError, RecordingWriteError
from .gaps import SEQUENCED_TYPES, GapTracker, sequence_span
from .mcapio import Decoders, check_file, iter_records
from .metadata import SEQUENCE_SOURCE_KEY, encode_metadata

RECOVERED_METADATA_NAME = 'rubber_rig.recovered'


@dataclass
class RecoverResult:
    source: str
    output: str
    was_complete: bool
    messages: int
    channels: int
    metadata_records: int
    samples_lost: int
    sequence_gaps: int
    last_log_time_ns: int = 0          # log time of the last message recovered (where intact data ends)
    last_sequence: int = None          # sequence of the last sample recovered (None: no samples)

    @property
    def tail_unaccounted(self) -> bool:
        """A truncated file lost an unknown number of samples after its last intact chunk."""
        return not self.was_complete

    def loss_text(self) -> str:
        known = f'{self.samples_lost} samples lost in {self.sequence_gaps} sequence gaps'
        if self.was_complete:
            return known
        seq = '' if self.last_sequence is None else f', last sample sequence {self.last_sequence}'
        return (f'{self.source} was NOT CLOSED (recorder killed or its writes failed): intact data ends at log '
                f'time {self.last_log_time_ns / 1e9:.3f} s{seq}; samples after that are unaccounted for '
                f'(unknown number); {known} within the intact data')


def recover(path, output=None, *, in_place: bool = False, backup: bool = True,
            chunk_size: int = 1 << 20) -> RecoverResult:
    """Copy every readable record of ``path`` into a complete MCAP file.

    ``output`` defaults to ``<name>.recovered.mcap``; with ``in_place`` the original is replaced
    (kept as ``<name>.mcap.bak`` if ``backup``).
    """
    path = Path(path)
    was_complete = check_file(path)           # raises RecordingError if not an MCAP file at all
    if in_place:
        target = path.with_name(path.name + '.recovering')
    else:
        target = Path(output) if output else path.with_name(path.stem + '.recovered.mcap')
    if target.resolve() == path.resolve():
        raise RecordingError(f'{path}: output must differ from the input (use --in-place)')
    counts = {'messages': 0, 'metadata': 0}
    gaps = GapTracker()
    decoders = Decoders(path)
    header_seen = False
    last = {'log_time': 0, 'sequence': None}
    try:
        with open(target, 'wb' if in_place else 'xb') as out:
            writer = McapWriter(out, chunk_size=chunk_size, compression=CompressionType.ZSTD)
            schemas, channels = {}, {}        # ids in the source -> ids in the output
            schema_records, channel_types = {}, {}
            for record in iter_records(path, allow_truncated=True):
                if isinstance(record, Header):
                    writer.start(record.profile, record.library)
                    header_seen = True
                elif isinstance(record, Schema) and record.id not in schemas:
                    schemas[record.id] = writer.register_schema(record.name, record.encoding,
                                                                record.data)
                    schema_records[record.id] = record
                elif isinstance(record, Channel) and record.id not in channels:
                    channels[record.id] = writer.register_channel(
                        record.topic, record.message_encoding, schemas.get(record.schema_id, 0),
                        dict(record.metadata))
                    channel_types[record.id] = (record.topic, schema_records.get(record.schema_id),
                                                record.metadata.get(SEQUENCE_SOURCE_KEY) == 'publication')
                elif isinstance(record, Message) and record.channel_id in channels:
                    writer.add_message(channels[record.channel_id], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                    counts['messages'] += 1
                    last['log_time'] = max(last['log_time'], record.log_time)
                    topic, schema, pubseq = channel_types[record.channel_id]
                    if schema is not None and schema.name in SEQUENCED_TYPES:
                        try:
                            msg = decoders.decode(schema, record.data, topic)
                            gaps.observe_message(topic, schema.name, msg, record.log_time,
                                                 record.sequence if pubseq else None)
                            span = sequence_span(schema.name, msg)
                            if span and span[1] and schema.name.endswith(('RigSampleBatch', 'RigSample')):
                                last['sequence'] = span[0] + span[1] - 1
                        except RecordingError:
                            pass
                elif isinstance(record, Metadata):
                    writer.add_metadata(record.name, dict(record.metadata))
                    counts['metadata'] += 1
                elif isinstance(record, Attachment):
                    writer.add_attachment(record.create_time, record.log_time, record.name,
                                          record.media_type, record.data)
            if not header_seen:
                raise RecordingError(f'{path}: no MCAP header record: nothing to recover')
            report = dict(gaps.summary(), source=str(path), was_complete=was_complete,
                          messages_recovered=counts['messages'],
                          gap_events=gaps.events, last_log_time_ns=last['log_time'],
                          last_sample_sequence=last['sequence'],
                          tail_unaccounted=not was_complete)
            writer.add_metadata(RECOVERED_METADATA_NAME, encode_metadata(report))
            writer.finish()
            out.flush()
            os.fsync(out.fileno())
    except FileExistsError:
        raise RecordingError(f'{target} exists already; choose another output with -o') from None
    except OSError as exc:
        _discard(target)
        raise _write_error(target, exc) from None
    except BaseException:
        _discard(target)
        raise
    if in_place:
        try:
            if backup:
                os.replace(path, path.with_name(path.name + '.bak'))
            os.replace(target, path)
        except OSError as exc:
            _discard(target)
            raise _write_error(Path(exc.filename or path), exc) from None
        target = path
        if (path.parent / METADATA_FILE).exists():   # part of a bag: index the recovered file too
            write_bag_metadata(path.parent)
    return RecoverResult(str(path), str(target), was_complete, counts['messages'], len(channels),
                         counts['metadata'], gaps.samples_lost, gaps.gaps, last['log_time'], last['sequence'])


def _write_error(target: Path, exc: OSError) -> RecordingWriteError:
    return RecordingWriteError(f'cannot write {target}: {exc.strerror or exc}', exc.errno or 0)


def _discard(target: Path):
    """Remove a partial output; on a path that could not be written (read-only file system, a parent
    that is not a directory, ...) removing fails the same way and there is nothing to remove.
    """
    try:
        target.unlink(missing_ok=True)
    except OSError:
        pass
