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

"""The parts of a split recording: which are there, which are missing, and how many samples those held.

A Recorder writes a recording as parts ``<name>_0.mcap``, ``<name>_1.mcap``, ... (session.Recorder). Each part
says where it belongs, in its own records, so that a directory years later still knows what it should hold:

- its ``rubber_rig`` record (written first): ``recording_id`` (one per recording), ``part_index``,
  ``samples_before`` (samples of the sample stream in the parts before it) and ``previous_last_sample``;
- its ``rubber_rig.close`` record (written when it is closed): ``part_samples``, ``first_sample``,
  ``last_sample`` (sequence numbers) and ``next_part`` (the file the recording continued in) or ``final_part``;
- the directory's ``metadata.yaml`` lists every part written in its custom_data (PARTS_KEY), the missing ones too.

:func:`survey` reads only these records (the files' summaries; an unclosed file up to its first record) of a
recording given as a directory or as any one of its parts, and says which parts are missing and how many samples
that is: a missing part between two present ones from the later one's ``samples_before`` (exact); a missing
first part likewise; missing last parts from the last present one's ``next_part`` and metadata.yaml (or "an
unknown number" without it). ``rubber-rig info`` and ``recover`` both print its :meth:`PartsReport.lines`.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Metadata

from .bagmeta import read_custom_data
from .errors import RecordingError
from .mcapio import RecordScan, recording_files
from .metadata import CLOSE_METADATA_NAME, METADATA_NAME, decode_metadata

RECORDING_ID_KEY = 'rubber_rig.recording_id'   # metadata.yaml custom_data: the recording's id
PARTS_KEY = 'rubber_rig.parts'                 # metadata.yaml custom_data: JSON list of the parts written


@dataclass
class Part:
    """One file of a recording as its own records describe it (None where a record does not say)."""

    file: str
    index: int | None
    recording_id: str = ''
    recording: str = ''
    closed: bool = True                     # has its footer (False: its writer was killed or failed)
    samples_before: int | None = None
    previous_last_sample: int | None = None
    samples: int | None = None              # from the close record
    first_sample: int | None = None
    last_sample: int | None = None
    next_part: str | None = None            # '' when the recording ended with this part; None: not said
    final: bool | None = None


@dataclass
class PartsReport:
    """What a survey found: the recording, its parts present and missing, and the samples the missing ones held."""

    recording: str = ''
    recording_id: str = ''
    present: list = field(default_factory=list)      # Part, in index order
    missing: list = field(default_factory=list)      # {'index', 'file', 'samples' (None: unknown), 'first', 'last',
    #                                                    'source'}
    after_last: str = ''                    # why parts after the last present one may be missing ('' if not)
    known: bool = True                      # the files carry part records (False: recorded before they did)

    @property
    def complete(self) -> bool:
        return not self.missing and not self.after_last

    @property
    def samples_missing(self) -> int:
        """Samples the missing parts held, as far as known."""
        return sum(m['samples'] or 0 for m in self.missing)

    @property
    def samples_unknown(self) -> bool:
        """Some missing part held an unknown number of samples."""
        return any(m['samples'] is None for m in self.missing) or bool(self.after_last)

    def as_dict(self) -> dict:
        return {'recording': self.recording, 'recording_id': self.recording_id, 'complete': self.complete,
                'parts_present': [p.index for p in self.present], 'parts_missing': self.missing,
                'samples_missing': self.samples_missing, 'samples_missing_unknown': self.samples_unknown,
                'after_last': self.after_last, 'part_records': self.known}

    def lines(self) -> list:
        """The parts in words, one finding per line (info and recover print the same lines)."""
        if not self.present:
            return []
        indices = [p.index for p in self.present]
        ident = f' (id {self.recording_id[:12]})' if self.recording_id else ''
        head = f'recording {self.recording or "?"}{ident}'
        if self.complete:
            ending = 'the last one closed as the end of the recording' if self.known else \
                'no part records (recorded by an older version): only the file numbering was checked'
            return [f'{head}: all {len(indices)} parts present ({_ranges(indices)}); {ending}']
        total = len(indices) + sum(1 + (m.get('through') or m['index']) - m['index'] for m in self.missing)
        out = [f'{head}: {total - len(indices)} of {total}{"+" if self.after_last else ""} parts MISSING, present: '
               f'{_ranges(indices)}']
        for m in self.missing:
            held = 'an unknown number of samples' if m['samples'] is None else f"{m['samples']} samples"
            seq = f", sequence {m['first']}..{m['last']}" if m.get('first') is not None and m.get('last') is not None \
                else ''
            which = f"parts {m['index']}..{m['through']}" if m.get('through') is not None else f"part {m['index']}"
            out.append(f"  {which} ({m['file']}) MISSING: {held}{seq} ({m['source']})")
        if self.after_last:
            out.append(f'  {self.after_last}')
        unknown = ' plus an unknown number' if self.samples_unknown else ''
        inside = any(indices[0] < m['index'] < indices[-1] for m in self.missing)
        out.append(f'  {self.samples_missing} samples{unknown} of the recording are in missing parts'
                   + (' (the sequence gap where a part is missing between two others counts the same samples)'
                      if inside else ''))
        return out


def _ranges(indices) -> str:
    return ', '.join(str(i) for i in indices)


def _int(value):
    try:
        return None if value is None or value == '' else int(value)
    except (TypeError, ValueError):
        return None


def _index_from_name(path: Path):
    m = re.search(r'_(\d+)$', path.name.removesuffix('.mcap').removesuffix('.recovered'))
    return int(m.group(1)) if m else None


def same_recording(path: str, new_path: str) -> bool:
    """True if ``new_path`` is a later part of the recording ``path`` is a part of (the recorder split it: same
    directory and name, a higher part number), e.g. ``r/r_0.mcap`` -> ``r/r_1.mcap``.
    """
    if not path or not new_path:
        return False
    a, b = Path(path), Path(new_path)
    ia, ib = _index_from_name(a), _index_from_name(b)
    stem = a.name.removesuffix('.mcap').rsplit('_', 1)[0]
    return (a.parent == b.parent and ia is not None and ib is not None and ib > ia
            and b.name.removesuffix('.mcap').rsplit('_', 1)[0] == stem)


def read_part(path) -> Part:
    """The part records of one file: from its summary (a closed file), else from its first records."""
    path = Path(path)
    header, close, closed = {}, {}, True
    try:
        with open(path, 'rb') as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None or not summary.metadata_indexes:
                raise ValueError('no summary')
            for m in reader.iter_metadata():
                if m.name == METADATA_NAME and not header:
                    header = decode_metadata(dict(m.metadata))
                elif m.name == CLOSE_METADATA_NAME:
                    close = decode_metadata(dict(m.metadata))
    except Exception:   # noqa: BLE001 - not closed (or no summary): read its first records, where the header is
        closed = False
        header = _first_header(path)
    index = _int(header.get('part_index', header.get('file_index')))
    return Part(str(path), index if index is not None else _index_from_name(path),
                recording_id=str(header.get('recording_id', '')), recording=str(header.get('recording', '')),
                closed=closed, samples_before=_int(header.get('samples_before')),
                previous_last_sample=_int(header.get('previous_last_sample')),
                samples=_int(close.get('part_samples')), first_sample=_int(close.get('first_sample')),
                last_sample=_int(close.get('last_sample')),
                next_part=close.get('next_part') if close else None,
                final=bool(close.get('final_part')) if 'final_part' in close else None)


def _first_header(path: Path) -> dict:
    try:
        for _, record in RecordScan(path):
            if isinstance(record, Metadata) and record.name == METADATA_NAME:
                return decode_metadata(dict(record.metadata))
    except RecordingError:
        pass
    return {}


def _siblings(path: Path) -> list:
    directory = path if path.is_dir() else path.parent
    try:
        return recording_files(directory)
    except RecordingError:
        return [path] if path.is_file() else []


def survey(path) -> PartsReport:
    """The parts of the recording that ``path`` (its directory, or any one of its files) belongs to."""
    path = Path(path)
    files = _siblings(path)
    parts = _adopt_unheaded([read_part(f) for f in files])
    if path.is_file():
        own = read_part(path)
        key = own.recording_id or own.recording
        parts = [p for p in parts if (p.recording_id or p.recording) == key] if key else [own]
    elif parts:
        ids = [p.recording_id or p.recording for p in parts]
        key = max(set(ids), key=ids.count)      # a directory holds one recording; strays are not its parts
        parts = [p for p in parts if (p.recording_id or p.recording) == key]
    custom = read_custom_data(path if path.is_dir() else path.parent)
    listed = {}
    if parts and custom.get(RECORDING_ID_KEY) == parts[0].recording_id and parts[0].recording_id:
        try:
            listed = {int(p['index']): p for p in json.loads(custom.get(PARTS_KEY, '[]'))}
        except (ValueError, TypeError, KeyError):
            listed = {}
    return assess(parts, listed)


def _adopt_unheaded(parts: list) -> list:
    """A part the recorder has just opened has no header on disk yet (it is written with the first flush): one
    whose file name continues a recording's (``<name>_<n>.mcap``) is that recording's part in progress, not a
    stranger, so a survey of a live recording does not call it missing.
    """
    named = {Path(p.file).name.removesuffix('.mcap').rsplit('_', 1)[0]: p for p in parts if p.recording_id}
    for p in parts:
        owner = named.get(Path(p.file).name.removesuffix('.mcap').rsplit('_', 1)[0])
        if not (p.recording_id or p.recording) and owner is not None and p.index is not None:
            p.recording_id, p.recording, p.closed = owner.recording_id, owner.recording, False
    return parts


def assess(parts: list, listed: dict = None) -> PartsReport:
    """Which parts are missing among ``parts`` (Part; any order) and the samples they held. ``listed``: the
    parts metadata.yaml names ({index: {'file', 'part_samples', 'first_sample', 'last_sample'}}).
    """
    listed = listed or {}
    by_index = {}
    for p in parts:
        if p.index is not None:
            by_index.setdefault(p.index, p)
    present = [by_index[i] for i in sorted(by_index)]
    report = PartsReport(present=present)
    if not present:
        return report
    first = present[0]
    report.recording, report.recording_id = first.recording, first.recording_id
    report.known = any(p.recording_id for p in present)
    name = first.recording or Path(first.file).name.rsplit('_', 1)[0]

    def missing(index, samples, first_seq, last_seq, source):
        entry = listed.get(index, {})
        if samples is None and entry:
            samples, source = _int(entry.get('part_samples')), 'metadata.yaml'
        if first_seq is None and entry:
            first_seq = _int(entry.get('first_sample'))
        if last_seq is None and entry:
            last_seq = _int(entry.get('last_sample'))
        report.missing.append({'index': index, 'file': entry.get('file', f'{name}_{index}.mcap'),
                               'samples': samples, 'first': first_seq, 'last': last_seq, 'source': source})

    previous = None
    for p in present:
        start = 0 if previous is None else previous.index + 1
        if p.index > start:      # parts start..p.index-1 are missing
            # their samples: what this part says came before it, less what the parts before it hold
            held = None
            known_before = previous is None or None not in (previous.samples_before, previous.samples)
            if p.samples_before is not None and known_before:
                held = p.samples_before - (0 if previous is None else previous.samples_before + previous.samples)
            first_seq = None if previous is None or previous.last_sample is None else previous.last_sample + 1
            run = list(range(start, p.index))
            if len(run) == 1 or all(_int(listed.get(i, {}).get('part_samples')) is not None for i in run):
                for i in run:
                    one = len(run) == 1
                    missing(i, held if one else None, first_seq if one else None,
                            p.previous_last_sample if one else None,
                            f'from the part records of {Path(p.file).name}' if one and held is not None
                            else 'no part records say')
            else:                # several in a row, not each listed: their total, once
                missing(run[0], held, first_seq, p.previous_last_sample,
                        f'parts {run[0]}..{run[-1]} together, from the part records of {Path(p.file).name}'
                        if held is not None else 'no part records say')
                report.missing[-1].update(through=run[-1], file=f'{name}_{run[0]}..{run[-1]}.mcap')
        previous = p
    last = present[-1]
    if last.next_part:   # closed as a split: the recording went on in a part that is not here
        more = sorted(i for i in listed if i > last.index)
        for i in more or [last.index + 1]:
            missing(i, None, last.last_sample + 1 if last.last_sample is not None and i == last.index + 1
                    else None, None, f'{Path(last.file).name} continued in it')
        if not more:
            report.after_last = (f'{Path(last.file).name} says the recording continued in {last.next_part}; '
                                 'no metadata.yaml lists the parts after it: they and their samples are unknown')
    return report
