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


"""The parts of docs/protocol.md that the DBC defines, generated from it: frames and signals, states, fault bits.

docs/protocol.md holds them between ``<!-- BEGIN GENERATED: name -->`` and ``<!-- END GENERATED: name -->``
markers; test_protocol_spec fails when they differ from what this module renders, so a DBC change cannot leave
the specification behind. After changing the DBC::

    python -m rubber_rig.rig.conformance.spec_doc        # rewrites the generated blocks of docs/protocol.md
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

from ..can.protocol import FAULT_NAMES, PROTOCOL_VERSION, STATES, Protocol

DOC = Path(__file__).resolve().parents[3] / 'docs' / 'protocol.md'
_BLOCK = re.compile(r'(<!-- BEGIN GENERATED: (\w+) -->\n)(.*?)(<!-- END GENERATED: \2 -->)', re.S)
_PER_SAMPLE = {'Setpoint', 'SetpointPacked', 'Feedback', 'FeedbackPacked', 'FeedbackApplied', 'FeedbackMeasured'}


def _cell(text) -> str:
    return str(text).replace('|', '/').replace('\n', ' ')


def _number(x) -> str:
    return f'{x:g}' if isinstance(x, float) else str(x)


def frame_table() -> str:
    """Every DBC message: identifier, sender, length, frame format, period, its comment, and its signals."""
    db = Protocol().db
    out = [f'Protocol version {PROTOCOL_VERSION} (`{db.version}`). Byte order little endian (Intel) for every '
           'signal; the last byte of every frame is its CRC-8.', '']
    out += ['| id | frame | sender | bytes | format | period |', '| --- | --- | --- | --- | --- | --- |']
    for m in sorted(db.messages, key=lambda m: m.frame_id):
        period = f'{m.cycle_time} ms' if m.cycle_time else ('per sample' if m.name in _PER_SAMPLE else 'on demand')
        out.append(f'| 0x{m.frame_id:03X} | {m.name} | {", ".join(m.senders)} | {m.length} | '
                   f'{"CAN FD" if m.is_fd else "classic"} | {period} |')
    for m in sorted(db.messages, key=lambda m: m.frame_id):
        out += ['', f'#### 0x{m.frame_id:03X} {m.name}', '', _cell(m.comment or ''), '',
                '| signal | start bit | bits | signed | scale | offset | unit | range | meaning |',
                '| --- | --- | --- | --- | --- | --- | --- | --- | --- |']
        for s in m.signals:
            meaning = s.comment or ''
            if s.choices:
                meaning = (meaning + ' ' if meaning else '') + ', '.join(f'{int(k)} {v}' for k, v in
                                                                         sorted(s.choices.items()))
            lo, hi = _number(s.minimum), _number(s.maximum)
            out.append(f'| {s.name} | {s.start} | {s.length} | {"yes" if s.is_signed else "no"} | '
                       f'{_number(s.scale)} | {_number(s.offset)} | {s.unit or "-"} | {lo} .. {hi} | '
                       f'{_cell(meaning)} |')
    return '\n'.join(out) + '\n'


def states_table() -> str:
    """The controller states (ST_State, HB_State)."""
    return '\n'.join(['| code | state |', '| --- | --- |'] + [f'| {i} | {s} |' for i, s in enumerate(STATES)]) + '\n'


def faults_table() -> str:
    """The fault bits (ST_Faults)."""
    rows = [f'| 0x{bit:02X} | {name} |' for bit, name in sorted(FAULT_NAMES.items())]
    return '\n'.join(['| bit | fault |', '| --- | --- |'] + rows) + '\n'


GENERATORS = {'frames': frame_table, 'states': states_table, 'faults': faults_table}


def generated_blocks(text: str) -> dict:
    """The content of each generated block in `text`, by block name."""
    return {m.group(2): m.group(3) for m in _BLOCK.finditer(text)}


def update_doc(path=DOC) -> bool:
    """Rewrite the generated blocks of `path` from the DBC; True if anything changed."""
    path = Path(path)
    text = path.read_text(encoding='utf-8')
    new = _BLOCK.sub(lambda m: m.group(1) + GENERATORS[m.group(2)]() + m.group(4), text)
    if new != text:
        path.write_text(new, encoding='utf-8')
    return new != text


if __name__ == '__main__':
    changed = update_doc(Path(sys.argv[1]) if len(sys.argv) > 1 else DOC)
    print(f'{DOC if len(sys.argv) < 2 else sys.argv[1]}: {"updated" if changed else "up to date"}')
