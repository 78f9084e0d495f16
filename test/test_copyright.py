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

ament_copyright is not on PyPI (the ros-jazzy wheels stop at flake8 and pep257), so where it is missing the
same check runs here: the copyright line and the license notice at the top of every Python file.
"""
import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ('rubber_rig', 'test', 'benchmarks', 'launch')
NOTICE = ('Licensed under the Apache License, Version 2.0 (the "License");',
          'http://www.apache.org/licenses/LICENSE-2.0',
          'limitations under the License.')


def _sources():
    yield ROOT / 'setup.py'
    for folder in FOLDERS:
        yield from sorted((ROOT / folder).rglob('*.py'))


@pytest.mark.copyright
@pytest.mark.linter
@pytest.mark.skipif(importlib.util.find_spec('ament_copyright') is None, reason='ament_copyright not installed')
def test_copyright():
    from ament_copyright.main import main
    rc = main(argv=[str(ROOT / f) for f in (*FOLDERS, 'setup.py')])
    assert rc == 0, 'Found errors'


@pytest.mark.copyright
@pytest.mark.linter
def test_every_source_file_carries_the_license_header():
    assert '<license>Apache-2.0</license>' in (ROOT / 'package.xml').read_text()
    missing = []
    for path in _sources():
        head = path.read_text(encoding='utf-8')[:1500]
        if not re.search(r'^# Copyright \d{4} \S', head, re.M) or not all(n in head for n in NOTICE):
            missing.append(str(path.relative_to(ROOT)))
    assert not missing, 'files without the Apache-2.0 header:\n' + '\n'.join(missing)
