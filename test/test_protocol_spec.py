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

"""docs/protocol.md, the rig protocol's specification, against the DBC and the requirement table: the
generated tables are what the DBC says, every requirement has its section (and nothing else does), the defect
table names real requirements, and the simulator cites the controller requirements it implements.
"""
import re
from pathlib import Path

from rubber_rig.rig.can.protocol import PROTOCOL_VERSION, Protocol
from rubber_rig.rig.conformance.defects import DEFECTS
from rubber_rig.rig.conformance.requirements import BY_ID, REQUIREMENTS
from rubber_rig.rig.conformance.spec_doc import DOC, GENERATORS, generated_blocks

ROOT = Path(__file__).resolve().parents[1]
TEXT = DOC.read_text(encoding='utf-8')


def test_generated_tables_are_what_the_dbc_says():
    blocks = generated_blocks(TEXT)
    assert set(blocks) == set(GENERATORS)
    for name, render in GENERATORS.items():
        assert blocks[name] == render(), (f'docs/protocol.md: the {name} table differs from the DBC: run '
                                          '`python -m rubber_rig.rig.conformance.spec_doc`')


def test_every_frame_and_signal_of_the_dbc_is_specified():
    for m in Protocol().db.messages:
        assert f'#### 0x{m.frame_id:03X} {m.name}' in TEXT
        for s in m.signals:
            assert f'| {s.name} |' in TEXT, s.name


def test_each_requirement_has_one_section_with_its_title_in_order():
    headings = re.findall(r'^### ([A-Z]+-[A-Z0-9]+-\d+): (.+)$', TEXT, re.M)
    assert [h[0] for h in headings] == [r.id for r in REQUIREMENTS]
    for rid, title in headings:
        assert title == BY_ID[rid].title


def test_the_document_states_the_protocol_version_of_the_dbc():
    assert re.search(r'^# rubber_rig rig protocol, version (\d+)$', TEXT, re.M).group(1) == str(PROTOCOL_VERSION)
    assert f'`rubber_rig {PROTOCOL_VERSION}`' in TEXT


def test_defects_break_specified_requirements_and_the_doc_lists_them():
    for name, (broken, _) in DEFECTS.items():
        assert set(broken) <= set(BY_ID), name
        row = next(line for line in TEXT.splitlines() if line.startswith(f'| `{name}` |'))
        assert row.rstrip(' |').endswith(', '.join(broken))


def test_the_simulator_cites_the_controller_requirements_it_implements():
    source = (ROOT / 'rubber_rig' / 'rig' / 'sim' / 'controller.py').read_text(encoding='utf-8')
    cited = set(re.findall(r'CTRL-[A-Z]+-\d+', source))
    assert cited <= set(BY_ID)
    for rid in ('CTRL-ID-1', 'CTRL-WD-1', 'CTRL-LIM-1', 'CTRL-LIM-2', 'CTRL-LIM-3', 'CTRL-STREAM-1',
                'CTRL-STREAM-2', 'CTRL-STREAM-3', 'CTRL-FRAME-2', 'CTRL-FRAME-3', 'CTRL-RESET-1', 'CTRL-FAULT-2',
                'CTRL-RAMP-1', 'CTRL-RAMP-2', 'CTRL-PWR-1', 'CTRL-HB-1', 'CTRL-ST-1'):
        assert rid in cited, rid
