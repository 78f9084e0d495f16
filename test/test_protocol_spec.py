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

"""docs/protocol.md, the rig protocol's specification, against the code that defines it: the generated tables
are what the DBC (and the conformance tables) say, every requirement has its section with its exact title (and
nothing else does), the defect table names real requirements, the protocol version is the DBC's, every frame and
signal is specified, the state machine is the one conformance checks, and the code each section cites exists.
"""
import re
from pathlib import Path

import pytest

from rubber_rig.rig.can.protocol import PROTOCOL_VERSION, STATES, Protocol
from rubber_rig.rig.conformance import spec_doc
from rubber_rig.rig.conformance.defects import DEFECTS
from rubber_rig.rig.conformance.passive import TRANSITIONS
from rubber_rig.rig.conformance.requirements import BY_ID, REQUIREMENTS
from rubber_rig.rig.conformance.spec_doc import DOC, GENERATORS, generated_blocks
from rubber_rig.rig.reference import REFERENCE_DEFECTS

ROOT = Path(__file__).resolve().parents[1]
TEXT = DOC.read_text(encoding='utf-8')
REGENERATE = 'run `python -m rubber_rig.rig.conformance.spec_doc` (and check the prose around the table)'


def requirement_sections() -> dict:
    """Requirement id -> (title, body) of each `### ID: title` section of the document, in document order."""
    out = {}
    for m in re.finditer(r'^### (\S+): ([^\n]+)\n(.*?)(?=^##)', TEXT + '\n## end\n', re.M | re.S):
        out[m.group(1)] = (m.group(2), m.group(3))
    return out


def test_generated_tables_are_what_the_dbc_says():
    """Each generated block is exactly what spec_doc renders now: a changed DBC fails until it is regenerated."""
    blocks = generated_blocks(TEXT)
    assert set(blocks) == set(GENERATORS), f'docs/protocol.md: generated blocks {sorted(blocks)}: {REGENERATE}'
    for name, render in GENERATORS.items():
        assert blocks[name] == render(), f'docs/protocol.md: the {name} table differs from the code: {REGENERATE}'


def test_update_doc_rewrites_only_the_generated_blocks(tmp_path):
    """update_doc restores a stale block, leaves the prose alone, and refuses a document without the markers."""
    copy = tmp_path / 'protocol.md'
    stale = TEXT.replace('| 0x702 | ControllerIdentity |', '| 0x702 | ControllerIdentityOld |')
    assert stale != TEXT
    copy.write_text(stale, encoding='utf-8')
    assert spec_doc.main([str(copy), '--check']) == 1
    assert spec_doc.update_doc(copy) is True
    assert copy.read_text(encoding='utf-8') == TEXT
    assert spec_doc.update_doc(copy) is False
    assert spec_doc.main([str(copy), '--check']) == 0
    copy.write_text('# no generated blocks\n', encoding='utf-8')
    with pytest.raises(ValueError, match='missing'):
        spec_doc.update_doc(copy)


def test_each_requirement_has_one_section_with_its_title_in_order():
    """The `### ` headings are exactly the requirements of requirements.py, in its order, with its titles."""
    headings = re.findall(r'^### (.*)$', TEXT, re.M)
    assert all(re.fullmatch(r'(CTRL|HOST)-[A-Z]+-\d+: \S.*', h) for h in headings), \
        [h for h in headings if not re.fullmatch(r'(CTRL|HOST)-[A-Z]+-\d+: \S.*', h)]
    ids = [h.split(':', 1)[0] for h in headings]
    assert ids == [r.id for r in REQUIREMENTS]
    for heading in headings:
        rid, title = heading.split(': ', 1)
        assert title == BY_ID[rid].title, rid


def test_each_requirement_says_how_it_is_checked_and_where_it_is_implemented():
    """Every section marks its check online/offline as requirements.py does, and names the reference code."""
    sections = requirement_sections()
    assert list(sections) == [r.id for r in REQUIREMENTS]
    for r in REQUIREMENTS:
        body = sections[r.id][1]
        mode = re.search(r'^- \*\*Check \(([a-z ]+)\):\*\* ', body, re.M)
        assert mode, f'{r.id}: no "- **Check (online|offline|online and offline|test suite):**" line'
        assert mode.group(1) in ('online', 'offline', 'online and offline', 'test suite'), r.id
        assert ('offline' in mode.group(1)) == r.offline, f'{r.id}: requirements.py says offline={r.offline}'
        assert re.search(r'^- \*\*Implemented in:\*\* ', body, re.M), f'{r.id}: no "Implemented in" line'


def test_the_code_the_specification_cites_exists():
    """Every `path`: `name` an "Implemented in" line cites is a file under rubber_rig/ defining that name."""
    cited = 0
    for rid, (_, body) in requirement_sections().items():
        line = re.search(r'^- \*\*Implemented in:\*\* (.*?)(?=^- |\Z)', body, re.M | re.S).group(1)
        line = ' '.join(line.split())
        parts = re.findall(r'`([\w/]+\.py)`: ((?:`[\w.]+`(?: \([^()]*\))?(?:, )?)+)', line)
        rebuilt = '; '.join(f'`{path}`: {names.rstrip(", ")}' for path, names in parts)
        assert rebuilt == line.rstrip('.'), f'{rid}: cite code as `path.py`: `name`, `name` (a note); `path.py`: ...'
        for path, names in parts:
            source = (ROOT / 'rubber_rig' / path).read_text(encoding='utf-8')
            for name in re.findall(r'`([\w.]+)`', re.sub(r'\([^)]*\)', '', names)):
                last = name.split('.')[-1]
                assert re.search(rf'^\s*(def|class) {last}\b|\b{last}\s*=', source, re.M), f'{rid}: {path}: {name}'
                cited += 1
    assert cited >= len(REQUIREMENTS)


def test_defects_break_specified_requirements():
    """Every requirement the defect table of defects.py names exists (the document lists the table generated)."""
    for name, (broken, what) in DEFECTS.items():
        assert broken and set(broken) <= set(BY_ID), name
        assert what, name
    assert '## Deliberate defects of the simulator' in TEXT


def test_reference_controller_defects_break_specified_requirements():
    """The second controller's defects (rig/reference/defects.py) name requirements that exist, and the document
    says what that controller is and answers the questions a controller written from it had to guess (issue 36).
    """
    for name, (broken, what) in REFERENCE_DEFECTS.items():
        assert broken and set(broken) <= set(BY_ID), name
        assert what, name
    assert '## A second controller written from this text' in TEXT
    for answer in ('**`CMD_RampVelocity` for HOLD.**', '**Minimum not below maximum.**',
                   '**Tighter limits with setpoints queued.**', '**A missing temperature.**', '**The first tick.**',
                   '**Sign of force and displacement.**'):
        assert answer in TEXT, answer


def test_the_document_states_the_protocol_version_of_the_dbc():
    """The title and the versioning section state the DBC's VERSION number."""
    assert re.search(r'^# rubber_rig rig protocol, version (\d+)$', TEXT, re.M).group(1) == str(PROTOCOL_VERSION)
    assert f'`rubber_rig {PROTOCOL_VERSION}`, version **{PROTOCOL_VERSION}**' in TEXT


def test_every_frame_and_signal_of_the_dbc_is_specified():
    """Each DBC message has its section and each of its signals its row."""
    for m in Protocol().db.messages:
        assert f'#### 0x{m.frame_id:03X} {m.name}\n' in TEXT, m.name
        for s in m.signals:
            assert f'\n| {s.name} | {s.start} | {s.length} |' in TEXT, s.name


def test_the_state_machine_is_the_one_conformance_checks():
    """The transitions of the state-machine table are passive.TRANSITIONS, between the DBC's states."""
    table = TEXT.split('| from | event | to | action | triggered by |', 1)[1].split('\n\n', 1)[0]
    rows = [[c.strip() for c in line.strip('|').split('|')] for line in table.strip().splitlines()[1:]]
    assert len(rows) >= len(TRANSITIONS)
    found = set()
    for row in rows:
        sources, to = row[0].split(', '), row[2]
        assert to in STATES or to == 'unchanged', row
        for src in sources:
            assert src in STATES or src in ('power-up', 'any'), row
            if src in STATES and to in STATES and src != to:
                found.add((src, to))
    assert found == TRANSITIONS


def test_the_simulator_cites_the_controller_requirements_it_implements():
    """The reference controller's comments name only specified requirements, and the ones it implements."""
    source = ''.join((ROOT / 'rubber_rig' / 'rig' / 'sim' / f'{part}.py').read_text(encoding='utf-8')
                     for part in ('controller', 'receive', 'transmit', 'state'))   # its tick, its parts, their state
    cited = set(re.findall(r'CTRL-[A-Z]+-\d+', source))
    assert cited <= set(BY_ID)
    for rid in ('CTRL-ID-1', 'CTRL-LIM-1', 'CTRL-LIM-2', 'CTRL-LIM-3', 'CTRL-STREAM-1', 'CTRL-STREAM-2',
                'CTRL-STREAM-3', 'CTRL-FRAME-2', 'CTRL-FRAME-3', 'CTRL-RESET-1', 'CTRL-FAULT-2', 'CTRL-RAMP-1',
                'CTRL-RAMP-2', 'CTRL-PWR-1', 'CTRL-HB-1', 'CTRL-ST-1', 'CTRL-WD-1'):
        assert rid in cited, rid
