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
"""ament_pep257 over the package, as ros2/demos runs it under colcon test.

The ignored checks are ruff.toml's docstring choices (summaries may run over two lines and may say what a
function returns, summary on the first line, no numpy section underlines) plus D403, which misreads a
CamelCase class name at the start of a summary as a badly capitalised word.
"""
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
IGNORE = ['D100', 'D101', 'D102', 'D103', 'D104', 'D105', 'D106', 'D107', 'D203', 'D205', 'D212', 'D213', 'D400',
          'D401', 'D402', 'D403', 'D404', 'D406', 'D407', 'D413', 'D415']


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    main = pytest.importorskip('ament_pep257.main').main
    rc = main(argv=['--ignore', *IGNORE, '--', str(ROOT / 'rubber_rig'), str(ROOT / 'launch'), str(ROOT / 'setup.py')])
    assert rc == 0, 'Found code style errors / warnings'
