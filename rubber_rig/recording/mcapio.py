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

"""Checked low-level access to MCAP files: every failure becomes a RecordingError naming the file and
the problem (bad magic, truncated, corrupt chunk, undecodable schema), never a library traceback.
"""
import io
import re
import struct
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.stream_reader import CRCValidationError, breakup_chunk

from .cdr import make_decoder
from .errors import RecordingError
from .mcap_compat import reference_decoder
from .metadata import decode_metadata  # importable from here as before

MAGIC = b'\x89MCAP0\r\n'
FOOTER_RECORD_SIZE = 1 + 8 + 8 + 8 + 4


def recording_files(path) -> list:
    """A file, a directory of split files (<name>_<i>.mcap, in index order) or a list of files."""
    if isinstance(path, (list, tuple)):
        return [Path(p) for p in path]
    path = Path(path)
    if path.is_dir():
        def index(p):
            m = re.search(r'_(\d+)$', p.stem.removesuffix('.recovered'))
            return (int(m.group(1)) if m else -1, p.name)
        files = sorted(path.glob('*.mcap'), key=index)
        # a file recovered next to its truncated original replaces it
        files = [f for f in files if not f.with_name(f.stem + '.recovered.mcap').exists()]
        if not files:
            raise RecordingError(f'{path}: directory holds no .mcap file')
        return files
    return [path]


def check_file(path: Path) -> bool:
    """Raise RecordingError if ``path`` is not an MCAP file; return True if it is complete (has its
    footer and closing magic), False if it ends early (writer killed: recover it).
    """
    if not path.exists():
        raise RecordingError(f'{path}: no such file')
    if path.is_dir():
        raise RecordingError(f'{path}: is a directory, not an MCAP file')
    size = path.stat().st_size
    with open(path, 'rb') as f:
        head = f.read(len(MAGIC))
        if head != MAGIC:
            what = 'empty file' if size == 0 else 'bad magic bytes at the start'
            raise RecordingError(f'{path}: not an MCAP file ({what})')
        if size < 2 * len(MAGIC) + FOOTER_RECORD_SIZE:
            return False
        f.seek(size - len(MAGIC) - FOOTER_RECORD_SIZE)
        tail = f.read()
    return tail[-len(MAGIC):] == MAGIC and tail[0] == 0x02


def truncated_message(path) -> str:
    return (f'{path}: truncated MCAP file (no footer/summary: the writer was killed or the disk filled '
            f'up); run `rubber-rig recover {path}` to rebuild it')


def _wrap(path, exc) -> RecordingError:
    text = str(exc) or type(exc).__name__
    if isinstance(exc, (EOFError, struct.error)) or 'EndOfFile' in type(exc).__name__:
        return RecordingError(truncated_message(path))
    if 'CRC' in type(exc).__name__ or 'crc' in text.lower():
        return RecordingError(f'{path}: corrupt MCAP data (checksum mismatch): {text}')
    return RecordingError(f'{path}: malformed MCAP file ({type(exc).__name__}: {text})')


# record opcodes of the MCAP specification. Private records (0x80-0xff), which a general reader skips, are refused
# like any other opcode: neither our writer nor rosbag2's writes them, and a chunk whose opcode byte was damaged
# would otherwise be skipped, its messages silently gone.
RECORDS = {0x01: Header, 0x02: Footer, 0x03: Schema, 0x04: Channel, 0x05: Message, 0x06: Chunk, 0x07: MessageIndex,
           0x08: ChunkIndex, 0x09: Attachment, 0x0A: AttachmentIndex, 0x0B: Statistics, 0x0C: Metadata,
           0x0D: MetadataIndex, 0x0E: SummaryOffset, 0x0F: DataEnd}
RECORD_HEAD = 9                # opcode (1) + record length (8)


class _Exact(ReadDataStream):
    """A record's bytes: reading past their end is an error (ReadDataStream returns a short read silently)."""

    def read(self, length: int) -> bytes:
        data = super().read(length)
        if len(data) != length:
            raise EndOfFile()
        return data


def _parse(opcode: int, content: bytes):
    """The record of ``content``, which its fields must fill exactly (a damaged length field shows here)."""
    stream = _Exact(io.BytesIO(content))
    cls = RECORDS[opcode]
    record = cls.read(stream, len(content)) if cls is Message else cls.read(stream)
    if stream.count != len(content):
        raise ValueError(f'its fields end {len(content) - stream.count} bytes before the record does')
    return record


class RecordScan:
    """Every record of one MCAP file in file order, checked, with the byte offset of each; chunks are broken up
    (their CRC checked) and their records yielded with the chunk's offset. Iterate it once.

    The file ends in one of three ways, told apart by where its bytes stop:

    - complete: the footer and the closing magic were read (``complete``);
    - truncated (a writer killed, a full disk, a power cut): the last record runs past the end of a file that has
      no footer, or the file ends between records, or in zero bytes only; ``intact_end`` is the offset where the
      readable data ends (iteration stops there, without an error);
    - corrupt: anything else, e.g. a chunk whose CRC does not match or that does not decompress, a record whose
      fields do not fill it exactly, an unknown or private opcode, or in a file that has its footer, a record that
      runs past its end: RecordingError naming the file, the record and its byte offset. Nothing after a corrupt
      record can be trusted, so nothing is skipped over.

    Records after DataEnd (the summary section, which ``recover`` rebuilds anyway) are parsed but not yielded;
    damage there is kept in ``summary_error`` rather than raised: the data before it is intact.
    """

    def __init__(self, path):
        self.path = Path(path)
        self.footer = check_file(self.path)   # RecordingError if not an MCAP file; True if it has its footer
        self.size = self.path.stat().st_size
        self.complete = False
        self.intact_end = None
        self.summary_error = None

    def _corrupt(self, offset: int, what: str) -> RecordingError:
        return RecordingError(f'{self.path}: corrupt MCAP file: {what} at byte offset {offset} (of {self.size}); '
                              'nothing from there on can be trusted')

    def _summary_damaged(self, text: str):
        self.summary_error = self.summary_error or text

    def __iter__(self):
        size = self.size
        in_summary = False
        with open(self.path, 'rb') as f:
            f.seek(len(MAGIC))
            pos = len(MAGIC)
            while True:
                if pos == size or (size - pos < RECORD_HEAD and not self.footer):
                    if self.footer and in_summary:         # the data section is whole; its summary is not
                        self._summary_damaged(f'the summary section ends at byte {pos} without its Footer')
                    elif self.footer:
                        raise self._corrupt(pos, 'the end of the file, without the Footer its last bytes promise,')
                    self.intact_end = pos
                    return
                head = f.read(RECORD_HEAD)
                if len(head) < RECORD_HEAD:
                    raise self._corrupt(pos, f'a record header cut short ({len(head)} of {RECORD_HEAD} bytes)')
                opcode, length = struct.unpack('<BQ', head)
                end = pos + RECORD_HEAD + length
                name = RECORDS[opcode].__name__ if opcode in RECORDS else f'record of opcode 0x{opcode:02x}'
                if opcode == 0 and not self.footer and _zeros(f, pos):
                    self.intact_end = pos                  # a power cut leaves the unwritten tail zero-filled
                    return
                if end > size and not self.footer:         # the record being written when the writer stopped
                    self.intact_end = pos
                    return
                problem = None
                if end > size:
                    problem = f'the {name} record claims {length} bytes, past the end of the file'
                elif pos == len(MAGIC) and opcode != 0x01:
                    problem = f'the first record is a {name}, not the Header'
                elif opcode not in RECORDS:
                    problem = f'a {name} (not a record of the MCAP specification)'
                if problem:
                    if in_summary:
                        self._summary_damaged(f'{problem} at byte {pos}')
                        return
                    raise self._corrupt(pos, problem)
                content = f.read(length)
                try:
                    record = _parse(opcode, content)
                except Exception as exc:  # noqa: BLE001 - the record classes raise many types on bad bytes
                    if in_summary:
                        self._summary_damaged(f'the {name} record at byte {pos} does not parse ({_why(exc)})')
                        return
                    raise self._corrupt(pos, f'the {name} record does not parse ({_why(exc)})') from None
                if isinstance(record, Chunk):
                    yield from ((pos, r) for r in self._chunk_records(record, pos))
                elif isinstance(record, Footer):
                    magic = f.read(len(MAGIC))
                    if len(magic) < len(MAGIC) and not self.footer:   # cut within the closing magic
                        self.intact_end = end
                        return
                    if magic != MAGIC:
                        raise self._corrupt(end, 'the closing magic after the Footer is damaged')
                    self.complete = True
                    self.intact_end = size
                    return
                elif not in_summary:
                    in_summary = isinstance(record, DataEnd)
                    yield pos, record
                pos = end

    def _chunk_records(self, chunk: Chunk, pos: int) -> list:
        what = f'the Chunk record (messages logged {chunk.message_start_time}..{chunk.message_end_time} ns)'
        try:
            return breakup_chunk(chunk, validate_crc=True)
        except CRCValidationError as exc:
            raise self._corrupt(pos, f'{what} fails its checksum (stored crc32 {exc.expected:#010x}, computed '
                                     f'{exc.actual:#010x})') from None
        except Exception as exc:  # noqa: BLE001 - decompression and parsing raise many types
            raise self._corrupt(pos, f'{what} does not decode ({_why(exc)})') from None


def _zeros(f, pos: int) -> bool:
    """True if the file holds only zero bytes from ``pos`` to its end (``f`` is left where it was)."""
    here = f.tell()
    f.seek(pos)
    try:
        while True:
            block = f.read(1 << 20)
            if not block:
                return True
            if block.count(0) != len(block):
                return False
    finally:
        f.seek(here)


def _why(exc: Exception) -> str:
    text = str(exc)
    return f'{type(exc).__name__}: {text}' if text else type(exc).__name__


def iter_records(path: Path, allow_truncated: bool):
    """All data-section records in file order (chunks broken up), checked (:class:`RecordScan`). A truncated tail
    ends the iteration if ``allow_truncated``, otherwise it raises; corruption always raises, naming the offset.
    """
    scan = RecordScan(path)
    for _, record in scan:
        yield record
    if not scan.complete and not allow_truncated:
        raise RecordingError(truncated_message(path))


def read_file(path: Path, allow_truncated: bool = False):
    """(schemas, channels, messages, metadata, complete) of one file; messages as
    (channel_id, log_time, publish_time, sequence, data) in file order (the order they were written).

    Damage is named where it is (:class:`RecordScan`): a complete file that the indexed reader cannot read is
    scanned record by record to find the bad one.
    """
    complete = check_file(path)
    if not complete and not allow_truncated:
        raise RecordingError(truncated_message(path))
    schemas, channels, messages, metadata = {}, {}, [], []
    if complete:
        try:
            with open(path, 'rb') as f:
                reader = make_reader(f, validate_crcs=True)
                summary = reader.get_summary()
                if summary is not None:
                    schemas.update(summary.schemas)
                    channels.update(summary.channels)
                for schema, channel, msg in reader.iter_messages(log_time_order=False):
                    if schema is not None:
                        schemas.setdefault(schema.id, schema)
                    channels.setdefault(channel.id, channel)
                    messages.append((msg.channel_id, msg.log_time, msg.publish_time, msg.sequence,
                                     msg.data))
                metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
            return schemas, channels, messages, metadata, True
        except RecordingError:
            raise
        except Exception as exc:  # noqa: BLE001 - turned into one clear error
            raise _locate(path, exc) from None
    for record in iter_records(path, allow_truncated=True):
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Message):
            messages.append((record.channel_id, record.log_time, record.publish_time, record.sequence,
                             record.data))
        elif isinstance(record, Metadata):
            metadata.append((record.name, dict(record.metadata)))
    return schemas, channels, messages, metadata, False


def _locate(path: Path, exc: Exception) -> RecordingError:
    """The error of a complete file the indexed reader failed on: the damaged record, found by a scan."""
    scan = RecordScan(path)
    for _ in scan:                  # raises RecordingError at a damaged record of the data section
        pass
    if scan.summary_error is None:
        return _wrap(path, exc)
    return RecordingError(f'{path}: the summary section of the MCAP file is damaged ({scan.summary_error}): '
                          f'{_why(exc)}; the data section is intact: `rubber-rig recover {path}` rebuilds the summary')


class Decoders:
    """CDR decoders generated from the schemas in the file (mcap_ros2, pure Python: no rclpy), cached
    per schema: the numpy decoder (cdr.make_decoder) where it applies, mcap_ros2's reference decoder
    where it does not or fails (big-endian, damaged).

    ``lazy_fallback`` (the writer's gap check): build the reference decoder only when it is first
    needed; by default it is built up front, which also rejects a schema it cannot parse.
    """

    def __init__(self, path, lazy_fallback: bool = False):
        self.path = path
        self.lazy_fallback = lazy_fallback
        self._cache = {}

    def _reference(self, schema: Schema, text: str):
        try:
            return reference_decoder(schema)
        except Exception as exc:  # noqa: BLE001
            raise RecordingError(f'{self.path}: cannot parse the schema of {schema.name}: '
                                 f'{exc}') from None

    def get(self, schema: Schema):
        """Decoders of a schema: [numpy decoder or None, reference decoder or None (lazy_fallback: not built yet)]."""
        key = (schema.name, schema.data)
        fns = self._cache.get(key)
        if fns is None:
            if schema.encoding != 'ros2msg':
                raise RecordingError(f'{self.path}: schema {schema.name} has encoding '
                                     f'{schema.encoding!r}; only ros2msg is supported')
            try:
                text = schema.data.decode()
            except Exception as exc:  # noqa: BLE001
                raise RecordingError(f'{self.path}: cannot parse the schema of {schema.name}: '
                                     f'{exc}') from None
            if self.lazy_fallback:
                fast = make_decoder(schema.name, text)
                fns = [fast, self._reference(schema, text) if fast is None else None]
            else:
                slow = self._reference(schema, text)
                fns = [make_decoder(schema.name, text), slow]
            self._cache[key] = fns
        return fns

    def decode(self, schema: Schema, data: bytes, topic: str):
        fns = self.get(schema)
        fast, slow = fns
        if fast is not None:
            try:
                return fast(data)
            except Exception:  # noqa: BLE001 - big-endian or damaged: the reference decoder decides
                pass
        if slow is None:                     # lazy_fallback: first message the numpy decoder refused
            slow = fns[1] = self._reference(schema, schema.data.decode())
        try:
            return slow(data)
        except Exception as exc:  # noqa: BLE001
            raise RecordingError(f'{self.path}: a {schema.name} message on {topic} does not decode '
                                 f'({type(exc).__name__}: {exc})') from None


__all__ = ['recording_files', 'check_file', 'read_file', 'iter_records', 'RecordScan', 'decode_metadata', 'Decoders']
