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
import re
import struct
from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

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


def iter_records(path: Path, allow_truncated: bool):
    """All records in file order (chunks broken up). A truncated tail ends the iteration if
    ``allow_truncated``; otherwise it raises.
    """
    with open(path, 'rb') as f:
        reader = StreamReader(f, skip_magic=False, validate_crcs=True, record_size_limit=1 << 31)
        it = reader.records
        while True:
            try:
                record = next(it)
            except StopIteration:
                return
            except Exception as exc:  # the mcap library raises assorted types on damage
                if allow_truncated:
                    return
                raise _wrap(path, exc) from None
            yield record


def read_file(path: Path, allow_truncated: bool = False):
    """(schemas, channels, messages, metadata, complete) of one file; messages as
    (channel_id, log_time, publish_time, sequence, data) in log-time order.
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
                for schema, channel, msg in reader.iter_messages(log_time_order=True):
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
            raise _wrap(path, exc) from None
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
    messages.sort(key=lambda m: m[1])
    return schemas, channels, messages, metadata, False


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


__all__ = ['recording_files', 'check_file', 'read_file', 'iter_records', 'decode_metadata', 'Decoders']
