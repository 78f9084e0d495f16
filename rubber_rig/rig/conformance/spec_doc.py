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


"""The parts of docs/protocol.md that code defines, rendered from it: frames and signals, state codes and fault
bits (rubber_rig.dbc), the tolerances of the offline checks (conformance.passive), the simulator's deliberate
defects (conformance.defects) and the time tolerances of the scenarios' verdicts (conformance.host_excuse).

docs/protocol.md holds each between ``<!-- BEGIN GENERATED: name -->`` and ``<!-- END GENERATED: name -->``
markers; test_protocol_spec fails when a block differs from what this module renders, so a change of the DBC
cannot leave the specification behind. After changing the DBC (or those tables)::

    python -m rubber_rig.rig.conformance.spec_doc           # rewrites the generated blocks of docs/protocol.md
    python -m rubber_rig.rig.conformance.spec_doc --check   # exit status 1 if they are out of date
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from ..can.frames import FEEDBACK_FRAMES, PROFILES, SETPOINT_FRAMES
from ..can.protocol import DBC_PATH, PROTOCOL_VERSION, Protocol
from ..reference.defects import REFERENCE_DEFECTS
from . import passive
from .defects import DEFECTS
from .host_excuse import TIME_TOLERANCE

DOC = Path(__file__).resolve().parents[3] / 'docs' / 'protocol.md'
REGENERATE = 'python -m rubber_rig.rig.conformance.spec_doc'
_BLOCK = re.compile(r'(<!-- BEGIN GENERATED: (\w+) -->\n)(.*?)(<!-- END GENERATED: \2 -->)', re.S)


def _cell(text) -> str:
    """Text for one Markdown table cell: a pipe escaped, line breaks folded."""
    return ' '.join(str(text).split()).replace('|', '\\|')


def _number(x) -> str:
    """A DBC number as the DBC means it: integers without a point, others in their shortest exact form."""
    if isinstance(x, float):
        return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)
    return str(x)


def _profiles(name: str) -> str:
    """The frame profiles (rig/can/frames.py) that carry samples in message `name`, '' for none."""
    return ', '.join(p for p in PROFILES if name in SETPOINT_FRAMES[p] + FEEDBACK_FRAMES[p])


def _period(m) -> str:
    if m.cycle_time:
        return f'{m.cycle_time} ms'
    profiles = _profiles(m.name)
    return f'per sample ({profiles})' if profiles else 'on demand'


def _meaning(m, s) -> str:
    """What a signal means: its DBC comment and VAL_ choices, and the conventions protocol.py and frames.py
    enforce (the last signal is the CRC, the first signal of a sample frame its sequence number).
    """
    parts = []
    if s is m.signals[-1]:
        parts.append('CRC-8 (SAE J1850) over the identifier (2 bytes, little endian) and the bytes before it.')
    elif s is m.signals[0] and _profiles(m.name):
        parts.append(f'Sample index modulo 2^{s.length}.')
    if s.comment:
        parts.append(s.comment)
    if s.choices:
        parts.append(', '.join(f'{int(k)} {v}' for k, v in sorted(s.choices.items())))
    return _cell(' '.join(parts))


def frame_table() -> str:
    """Every DBC message: identifier, sender, length, frame format, period, its comment, and its signals."""
    db = Protocol().db
    messages = sorted(db.messages, key=lambda m: m.frame_id)
    out = [f'Protocol version {PROTOCOL_VERSION} (`{db.version}`), from `rubber_rig/rig/can/{DBC_PATH.name}`. '
           'Every identifier is 11 bits (standard frame). Every signal is little endian (Intel byte order); a '
           'start bit counts from bit 0, the least significant bit of byte 0. Physical value = raw x scale + '
           'offset. The last byte of every frame is its CRC-8.', '',
           '| id | frame | sender | bytes | format | period |', '| --- | --- | --- | --- | --- | --- |']
    for m in messages:
        out.append(f'| 0x{m.frame_id:03X} | {m.name} | {", ".join(m.senders)} | {m.length} | '
                   f'{"CAN FD" if m.is_fd else "classic"} | {_period(m)} |')
    for m in messages:
        out += ['', f'#### 0x{m.frame_id:03X} {m.name}', '', _cell(m.comment or ''), '',
                '| signal | start bit | bits | signed | scale | offset | unit | range | meaning |',
                '| --- | --- | --- | --- | --- | --- | --- | --- | --- |']
        for s in m.signals:
            lo = '-' if s.minimum is None else _number(s.minimum)
            hi = '-' if s.maximum is None else _number(s.maximum)
            out.append(f'| {s.name} | {s.start} | {s.length} | {"yes" if s.is_signed else "no"} | '
                       f'{_number(s.scale)} | {_number(s.offset)} | {s.unit or "-"} | {lo} .. {hi} | '
                       f'{_meaning(m, s)} |')
    return '\n'.join(out) + '\n'


def _carriers(reference):
    """The signals (message, signal) whose VAL_ table is the one of `reference`, and that table."""
    db = Protocol().db
    choices = {int(k): str(v) for k, v in db.get_message_by_name(reference[0]).get_signal_by_name(reference[1])
               .choices.items()}
    carriers = [(m, s) for m in db.messages for s in m.signals
                if s.choices and {int(k): str(v) for k, v in s.choices.items()} == choices]
    return carriers, choices


def states_table() -> str:
    """The controller state codes (VAL_ ST_State, repeated by every signal with the same table)."""
    carriers, choices = _carriers(('ControllerStatus', 'ST_State'))
    width = min(s.length for _, s in carriers)
    names = ' and '.join(f'{s.name} ({m.name})' for m, s in carriers)
    out = [f'Carried in {names}. Codes {max(choices) + 1}..{(1 << width) - 1} are not defined.', '',
           '| code | state |', '| --- | --- |']
    out += [f'| {code} | {name} |' for code, name in sorted(choices.items())]
    return '\n'.join(out) + '\n'


def faults_table() -> str:
    """The fault bits (VAL_ ST_Faults): one row per bit."""
    carriers, choices = _carriers(('ControllerStatus', 'ST_Faults'))
    width = min(s.length for _, s in carriers)
    used = [code.bit_length() - 1 for code in choices]
    names = ' and '.join(f'{s.name} ({m.name})' for m, s in carriers)
    out = [f'Carried in {names}, one bit per fault. Bits {max(used) + 1}..{width - 1} are not defined and are '
           'always 0.', '', '| bit | mask | fault |', '| --- | --- | --- |']
    out += [f'| {code.bit_length() - 1} | 0x{code:04X} | {name} |' for code, name in sorted(choices.items())]
    return '\n'.join(out) + '\n'


# what each tolerance of the offline checks (conformance/passive.py) is for: (constant, shown as: '%' a share,
# 'ms' a time in seconds, 'x' a factor; what it bounds)
_TOLERANCES = (
    ('PERIOD_TOLERANCE', '%', 'median interval of a periodic frame within +- this share of its GenMsgCycleTime '
     '(CTRL-HB-1, CTRL-ST-1, CTRL-TEMP-1, CTRL-ID-2)'),
    ('GAP_FACTOR', 'x', '99 % of the intervals of a periodic frame at most this many cycle times (the host '
     "watchdog's margin; also HostHeartbeat, HOST-HB-1)"),
    ('HOST_SILENCE', 'ms', 'no interval of a periodic frame may be longer than this (the driver\'s default '
     'watchdog_timeout) or GAP_FACTOR cycle times if that is longer: a host faults at such a silence (CTRL-HB-1, '
     'CTRL-ST-1, CTRL-TEMP-1, CTRL-ID-2)'),
    ('RATE_TOLERANCE', '%', 'feedback sample rate within +- this share of the configured rate over every run of '
     'feedback of 0.5 s or more (CTRL-FB-1)'),
    ('JITTER_MAX', 'ms', '99th minus 1st percentile of the arrival delay of every feedback sample (each sample of '
     'a packed frame arrives with its frame) after a linear fit of arrival time against sequence (CTRL-FB-2)'),
    ('STATUS_LEAD', 'ms', 'how far ST_LastSequence may be ahead of the last feedback sample received, in samples at '
     'the sample rate, plus 6 (one packed feedback frame); it may be at most 6 behind (CTRL-ST-3)'),
    ('RUN_BREAK', 'ms', 'a status frame this much later than the last feedback is not compared with it (CTRL-ST-3); '
     'runs of feedback end only at a status of a state that takes no tick, never at a silence, so continuity '
     '(CTRL-SEQ-1) is judged across stalls of any length'),
    ('STALL_MAX', 'ms', 'the longest silence between two feedback frames while the controller ticks (CTRL-FB-2)'),
)


def tolerances_table() -> str:
    """The tolerances of the checks a trace alone can judge, with their values from conformance/passive.py."""
    out = ['| constant (`conformance/passive.py`) | value | what it bounds |', '| --- | --- | --- |']
    for name, unit, what in _TOLERANCES:
        value = getattr(passive, name)
        shown = {'%': f'{value * 100:g} %', 'ms': f'{value * 1e3:g} ms', 'x': f'{value:g} x'}[unit]
        out.append(f'| `{name}` | {shown} | {_cell(what)} |')
    return '\n'.join(out) + '\n'


def defects_table() -> str:
    """The simulator's deliberate defects (conformance/defects.py) and the requirements each one breaks."""
    out = ['| defect | what the simulated controller then does | requirements it breaks |', '| --- | --- | --- |']
    out += [f'| `{name}` | {_cell(what)} | {", ".join(broken)} |' for name, (broken, what) in DEFECTS.items()]
    return '\n'.join(out) + '\n'


def reference_defects_table() -> str:
    """The reference controller's deliberate defects (rig/reference/defects.py) and the requirements each breaks."""
    out = ['| defect | what the reference controller then does | requirements it breaks |', '| --- | --- | --- |']
    out += [f'| `{name}` | {_cell(what)} | {", ".join(broken)} |'
            for name, (broken, what) in REFERENCE_DEFECTS.items()]
    return '\n'.join(out) + '\n'


def host_excuses_table() -> str:
    """The time tolerance of each requirement a scenario judges (conformance/host_excuse.py): this host late this
    long without a break in a FAIL's stretch makes it not judged.
    """
    out = ['| requirement | time tolerance | what it is |', '| --- | --- | --- |']
    out += [f'| {rid} | {seconds * 1e3:g} ms | {_cell(what)} |' for rid, (seconds, what) in TIME_TOLERANCE.items()]
    return '\n'.join(out) + '\n'


GENERATORS = {'frames': frame_table, 'states': states_table, 'faults': faults_table,
              'tolerances': tolerances_table, 'defects': defects_table, 'reference_defects': reference_defects_table,
              'host_excuses': host_excuses_table}


def generated_blocks(text: str) -> dict:
    """The content of each generated block in `text`, by block name."""
    return {m.group(2): m.group(3) for m in _BLOCK.finditer(text)}


def render(text: str) -> str:
    """`text` with every generated block rendered anew; ValueError if a block is missing or unknown."""
    names = [m.group(2) for m in _BLOCK.finditer(text)]
    missing, unknown = set(GENERATORS) - set(names), set(names) - set(GENERATORS)
    if missing or unknown or len(names) != len(set(names)):
        raise ValueError(f'generated blocks: missing {sorted(missing)}, unknown {sorted(unknown)}, '
                         f'{len(names) - len(set(names))} repeated (expected each of {", ".join(GENERATORS)} once)')
    return _BLOCK.sub(lambda m: m.group(1) + GENERATORS[m.group(2)]() + m.group(4), text)


def update_doc(path=DOC) -> bool:
    """Rewrite the generated blocks of `path` (default docs/protocol.md); True if anything changed."""
    path = Path(path)
    text = path.read_text(encoding='utf-8')
    new = render(text)
    if new != text:
        path.write_text(new, encoding='utf-8')
    return new != text


def main(argv=None) -> int:
    """Command line: update the generated blocks of the specification (or, with --check, only compare)."""
    parser = argparse.ArgumentParser(prog=REGENERATE, description='Regenerate the tables of docs/protocol.md '
                                     'from rubber_rig.dbc, conformance/passive.py and conformance/defects.py.')
    parser.add_argument('path', nargs='?', default=str(DOC), help='the specification (default: %(default)s)')
    parser.add_argument('--check', action='store_true', help='change nothing; exit status 1 if out of date')
    args = parser.parse_args(argv)
    path = Path(args.path)
    try:
        if args.check:
            text = path.read_text(encoding='utf-8')
            stale = render(text) != text
            print(f'{path}: {"out of date (run " + REGENERATE + ")" if stale else "up to date"}')
            return 1 if stale else 0
        print(f'{path}: {"updated" if update_doc(path) else "up to date"}')
    except (OSError, ValueError) as exc:
        print(f'{REGENERATE}: {exc}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
