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
"""Every source file carries the Apache-2.0 header of package.xml's license, as ament_copyright checks it.

ament_copyright is not on PyPI (the ros-jazzy wheels of the ament linters stop at flake8 and pep257), so
test_copyright, the test ros2/demos has, skips here and runs where ROS is installed. The same check runs
everywhere in test_every_source_file_has_the_header_ament_copyright_accepts, ported from ament_copyright
0.17 (parser.py, main.py): after any shebang / coding lines and empty lines, the first block of consecutive
``#`` lines holds a line ``Copyright <year>[-<year>][, <year>...] <holder>`` (any holder; ``(c)`` optional),
and the rest of that block contains the text of its template apache2_header.txt, compared with runs of white
space collapsed. An empty file passes, as there.
"""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# what colcon test would hand ament_copyright for this package: its Python packages, tests, benchmarks, launch
# files and setup.py (not build/ or the venv, which a checkout holds and a colcon source space does not)
FOLDERS = ('rubber_rig', 'test', 'benchmarks', 'launch')
EXTENSIONS = {'.c', '.cc', '.cpp', '.cxx', '.h', '.hh', '.hpp', '.hxx', '.cmake', '.py'}   # ament_copyright's
# ament_copyright/template/apache2_header.txt, after its '{copyright}' line
APACHE2_HEADER = '''
Licensed under the Apache License, Version 2.0 (the "License");
you may not use this file except in compliance with the License.
You may obtain a copy of the License at

    http://www.apache.org/licenses/LICENSE-2.0

Unless required by applicable law or agreed to in writing, software
distributed under the License is distributed on an "AS IS" BASIS,
WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
See the License for the specific language governing permissions and
limitations under the License.'''
_YEARS = r'(?:\d{4}|\d{4}-\d{4})'
COPYRIGHT_LINE = re.compile(r'^[^\n\r]?\s*(?:\\copyright\s*)?copyright(?:\s+\(c\))?\s+(%s(?:,\s*%s)*),?\s+([^\n\r]+)$'
                            % (_YEARS, _YEARS), re.DOTALL | re.MULTILINE | re.IGNORECASE)


def _collapse(text: str) -> str:
    return ' '.join(text.split())


def ament_copyright_finding(content: str):
    """What ament_copyright says of a Python source file that is not an Apache-2.0 file, or None if it is."""
    if not content:
        return None                                          # 'file empty': not an error
    lines = content.lstrip('\ufeff').splitlines()
    i = 0
    while i < len(lines) and lines[i].startswith('#') and (lines[i].startswith('#!') or 'coding=' in lines[i]
                                                           or 'coding:' in lines[i]):
        i += 1
    while i < len(lines) and lines[i] == '':
        i += 1
    start = next((k for k in range(i, len(lines)) if lines[k].startswith('#')), None)
    if start is None:
        return 'could not find copyright notice'
    end = start
    while end < len(lines) and lines[end].startswith('#'):
        end += 1
    block = '\n'.join(line[2:] for line in lines[start:end])   # without the comment token and one space
    holders, rest = [], block
    while (match := COPYRIGHT_LINE.search(rest)) is not None:
        holders.append(f'{match.group(2)} ({match.group(1)})')
        rest = rest[match.end(2):]
    if not holders:
        return 'could not find copyright notice'
    if _collapse(APACHE2_HEADER) not in _collapse(rest):
        return f'copyright={", ".join(holders)}, license=<unknown> (not the Apache-2.0 notice)'
    return None


def _sources():
    yield ROOT / 'setup.py'
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob('*')):
            parts = path.relative_to(ROOT).parts
            if path.suffix in EXTENSIONS and path.is_file() and not any(p[0] in '._' for p in parts[:-1]):
                yield path


@pytest.mark.copyright
@pytest.mark.linter
def test_copyright():
    main = pytest.importorskip('ament_copyright.main').main
    rc = main(argv=[str(ROOT / f) for f in (*FOLDERS, 'setup.py')])
    assert rc == 0, 'Found errors'


@pytest.mark.copyright
@pytest.mark.linter
def test_every_source_file_has_the_header_ament_copyright_accepts():
    assert '<license>Apache-2.0</license>' in (ROOT / 'package.xml').read_text()
    assert _collapse((ROOT / 'LICENSE').read_text()).startswith('Apache License Version 2.0, January 2004')
    findings = [f'{path.relative_to(ROOT)}: {finding}' for path in _sources()
                if (finding := ament_copyright_finding(path.read_text(encoding='utf-8'))) is not None]
    assert not findings, 'files without the Apache-2.0 header:\n' + '\n'.join(findings)


HEADER = '# Copyright 2026 rubber_rig developers\n#\n' + ''.join(
    f'# {line}'.rstrip() + '\n' for line in APACHE2_HEADER.lstrip('\n').split('\n'))


@pytest.mark.parametrize('text', [
    HEADER + '"""Docstring."""\n',
    '#!/usr/bin/env python3\n# -*- coding: utf-8 -*-\n\n' + HEADER,
    HEADER.replace('Copyright 2026', 'Copyright (c) 2024-2026, 2027'),
    HEADER.replace('\n# Licensed under', '\n#     Licensed    under'),                  # white space is free
    '',
])
def test_the_header_check_accepts_what_ament_copyright_accepts(text):
    assert ament_copyright_finding(text) is None


@pytest.mark.parametrize('text, finding', [
    ('"""No header."""\n', 'could not find copyright notice'),
    ('"""Docstring first."""\n' + HEADER.replace('# Copyright', '# Copyleft'), 'could not find copyright notice'),
    (HEADER.replace('#\n# Licensed', '\n# Licensed'), 'license=<unknown>'),            # notice cut off the block
    (HEADER.replace('"AS IS" BASIS', 'AS IS BASIS'), 'license=<unknown>'),
    (HEADER.replace('# limitations under the License.\n', ''), 'license=<unknown>'),
])
def test_the_header_check_refuses_what_ament_copyright_refuses(text, finding):
    assert finding in ament_copyright_finding(text)
