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

"""The text CAN logs (.asc, candump .log) read line by line: TextLogReader hands each line to python-can's own
parser and skips (and counts) a line that is unreadable - not UTF-8, binary bytes, not a frame line of the
format, a frame python-can cannot parse or one with fewer data bytes than its length field says - so one bad line
costs that line only; also the integrity checks of a log's end and the ASC start time (canlog_reader uses them).
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import can
from can.io.asc import ASC_MESSAGE_REGEX

from .canlog import SUPPORTED_FORMATS, CanLogError, log_format

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
            if not raw.endswith(b'\n') and raw.strip():
                owner.cut_line = owner.lines   # the file ends inside this line: whatever it holds is cut short
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
      CAN FD frame has (a line cut short);
    - a frame on the last line when the file ends inside it, without its newline (``cut_line``: the log is
      truncated; a cut candump -L line can look like a shorter frame).

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
        self.cut_line = None   # number of the last line when the file ends inside it (truncated), else None

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
                        # a frame on a line the file ends inside may have lost data bytes nothing else shows
                        # (candump -L has no length field): never a frame, always the log's damage
                        problem = ('the file ends inside this line (the log is truncated)'
                                   if self.cut_line is not None and self.lines == self.cut_line
                                   else _frame_problem(msg))
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


def text_damage(p: Path, reader: TextLogReader, out) -> None:
    """The skipped lines of a text log into the CanLog `out`; CanLogError if nothing in the file could be read."""
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
