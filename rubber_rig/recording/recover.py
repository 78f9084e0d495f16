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
writer could not write is recomputed from the data by the loss ledger (gaps.LossLedger, the one the recorder
and ``rubber-rig info`` keep, so ``info`` on the recovered file shows the same numbers) and stored in a
``rubber_rig.recovered`` metadata record. Like ``mcap recover`` of the Go CLI, but in Python.

A damaged file is refused, not copied in part: a chunk that fails its checksum, a record that does not parse,
or in a file that has its footer a record running past its end raise RecordingError naming the file, the record
and its byte offset (mcapio.RecordScan); nothing is written. Only a file that *ends* early is truncated.
"""
import os
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from .bagmeta import METADATA_FILE, write_bag_metadata
from .errors import RecordingError, RecordingWriteError
from .gaps import SAMPLE_TYPES, LossLedger, sequence_span
from .mcapio import Decoders, RecordScan
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
    loss: dict = field(default_factory=dict)   # the loss ledger's counts (gaps.LossLedger.summary)
    intact_end: int = None             # byte offset where the readable data of the source ends
    size: int = 0                      # bytes in the source
    summary_error: str = None          # a complete source whose summary section was damaged: where
    undecodable: int = 0               # sample messages copied whose bytes do not decode (not in the ledger)

    @property
    def tail_unaccounted(self) -> bool:
        """A truncated file lost an unknown number of samples after its last intact chunk."""
        return not self.was_complete

    def loss_text(self) -> str:
        known = f'{self.samples_lost} samples lost in {self.sequence_gaps} sequence gaps'
        if self.loss.get('sequence_jumps'):
            known += f' ({self.loss["sequence_jumps"]} sequence jumps between programs, not loss)'
        if self.undecodable:
            known += f'; {self.undecodable} sample messages do not decode and are not counted'
        if self.was_complete:
            return known
        seq = '' if self.last_sequence is None else f', last sample sequence {self.last_sequence}'
        return (f'{self.source} was NOT CLOSED (recorder killed or its writes failed): intact data ends at byte '
                f'{self.intact_end} of {self.size}, log time {self.last_log_time_ns / 1e9:.3f} s{seq}; samples '
                f'after that are unaccounted for (unknown number); {known} within the intact data')


def recover(path, output=None, *, in_place: bool = False, backup: bool = True,
            chunk_size: int = 1 << 20) -> RecoverResult:
    """Copy every readable record of ``path`` into a complete MCAP file.

    ``output`` defaults to ``<name>.recovered.mcap``; with ``in_place`` the original is replaced
    (kept as ``<name>.mcap.bak`` if ``backup``). A corrupt file raises RecordingError (nothing is written).
    """
    path = Path(path)
    scan = RecordScan(path)                   # raises RecordingError if not an MCAP file at all
    was_complete = scan.footer
    if in_place:
        target = path.with_name(path.name + '.recovering')
    else:
        target = Path(output) if output else path.with_name(path.stem + '.recovered.mcap')
    if target.resolve() == path.resolve():
        raise RecordingError(f'{path}: output must differ from the input (use --in-place)')
    try:
        with open(target, 'wb' if in_place else 'xb') as out:
            copier = _Copier(McapWriter(out, chunk_size=chunk_size, compression=CompressionType.ZSTD), path)
            for _, record in scan:            # file order: the order the recorder wrote (and counted) them
                copier.copy(record)
            if not copier.header_seen:
                raise RecordingError(f'{path}: no complete MCAP header record: nothing to recover')
            loss, counts, last = copier.ledger.summary(), copier.counts, copier.last
            report = dict(loss, source=str(path), was_complete=was_complete,
                          messages_recovered=counts['messages'], undecodable_sample_messages=counts['undecodable'],
                          gap_events=copier.ledger.events, last_log_time_ns=last['log_time'],
                          last_sample_sequence=last['sequence'], intact_end=scan.intact_end,
                          source_size=scan.size, summary_error=scan.summary_error or '',
                          tail_unaccounted=not was_complete)
            copier.writer.add_metadata(RECOVERED_METADATA_NAME, encode_metadata(report))
            copier.writer.finish()
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
        target = _replace(path, target, backup)
    return RecoverResult(str(path), str(target), was_complete, counts['messages'], len(copier.channels),
                         counts['metadata'], loss['samples_lost'], loss['sequence_gaps'], last['log_time'],
                         last['sequence'], loss, scan.intact_end, scan.size, scan.summary_error,
                         counts['undecodable'])


class _Copier:
    """Writes the records of a scanned file into `writer`, renumbering schemas and channels, and counts the
    sample loss of what it copies in one LossLedger (the recorder's own bookkeeping, so both count alike).
    """

    def __init__(self, writer, path):
        self.writer, self.decoders = writer, Decoders(path)
        self.counts = {'messages': 0, 'metadata': 0, 'undecodable': 0}
        self.ledger = LossLedger()
        self.header_seen = False
        self.last = {'log_time': 0, 'sequence': None}
        self.schemas, self.channels = {}, {}        # ids in the source -> ids in the output
        self.schema_records, self.channel_types = {}, {}

    def copy(self, record) -> None:
        """Copy one record (a second schema or channel with a known id is a repeat: skipped)."""
        w = self.writer
        if isinstance(record, Header):
            w.start(record.profile, record.library)
            self.header_seen = True
        elif isinstance(record, Schema) and record.id not in self.schemas:
            self.schemas[record.id] = w.register_schema(record.name, record.encoding, record.data)
            self.schema_records[record.id] = record
        elif isinstance(record, Channel) and record.id not in self.channels:
            self.channels[record.id] = w.register_channel(record.topic, record.message_encoding,
                                                          self.schemas.get(record.schema_id, 0),
                                                          dict(record.metadata))
            self.channel_types[record.id] = (record.topic, self.schema_records.get(record.schema_id),
                                             record.metadata.get(SEQUENCE_SOURCE_KEY) == 'publication')
        elif isinstance(record, Message) and record.channel_id in self.channels:
            w.add_message(self.channels[record.channel_id], record.log_time, record.data, record.publish_time,
                          record.sequence)
            self.counts['messages'] += 1
            self.last['log_time'] = max(self.last['log_time'], record.log_time)
            self._observe(record)
        elif isinstance(record, Metadata):
            w.add_metadata(record.name, dict(record.metadata))
            self.counts['metadata'] += 1
        elif isinstance(record, Attachment):
            w.add_attachment(record.create_time, record.log_time, record.name, record.media_type, record.data)

    def _observe(self, record) -> None:
        topic, schema, pubseq = self.channel_types[record.channel_id]
        if schema is None or schema.name not in SAMPLE_TYPES:
            return
        try:
            msg = self.decoders.decode(schema, record.data, topic)
        except RecordingError:   # copied as it is; the recorder did not count it either
            self.counts['undecodable'] += 1
            return
        self.ledger.observe(topic, schema.name, msg, record.log_time, record.sequence if pubseq else None)
        span = sequence_span(schema.name, msg)
        if span and span[1]:
            self.last['sequence'] = span[0] + span[1] - 1


def _replace(path: Path, target: Path, backup: bool) -> Path:
    """Put the recovered `target` in the place of `path` (the original kept as .bak if `backup`)."""
    try:
        if backup:
            os.replace(path, path.with_name(path.name + '.bak'))
        os.replace(target, path)
    except OSError as exc:
        _discard(target)
        raise _write_error(Path(exc.filename or path), exc) from None
    if (path.parent / METADATA_FILE).exists():   # part of a bag: index the recovered file too
        write_bag_metadata(path.parent)
    return path


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
