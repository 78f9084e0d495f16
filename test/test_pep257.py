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

The ignored checks are setup.cfg's [pep257] list, ruff.toml's docstring choices (a plain `pydocstyle` in the
checkout reads the same list). ament_pep257 passes its own --ignore, which overrides a configuration file, so
the list is handed to it here. Like ruff.toml, no docstring checks for test/.
"""
import configparser
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def ignored() -> list:
    config = configparser.ConfigParser()
    config.read(ROOT / 'setup.cfg')
    return [code.strip() for code in config['pep257']['ignore'].split(',') if code.strip()]


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    main = pytest.importorskip('ament_pep257.main').main
    rc = main(argv=['--ignore', *ignored(), '--', *(str(ROOT / p) for p in ('rubber_rig', 'benchmarks', 'launch',
                                                                            'setup.py'))])
    assert rc == 0, 'Found code style errors / warnings'


def test_the_ignored_checks_are_ruffs():
    """Every check ruff.toml ignores is ignored here too (ruff's pep257 convention leaves out more)."""
    ruff = tomllib.loads((ROOT / 'ruff.toml').read_text())['lint']
    assert {c for c in ruff['ignore'] if c.startswith('D')} <= set(ignored())
    assert ruff['pydocstyle']['convention'] == 'pep257' and ruff['per-file-ignores']['test/*'] == ['D']
