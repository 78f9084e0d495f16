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
"""ament_flake8 over the package, as ros2/demos runs it under colcon test.

ros2/demos calls main_with_errors(argv=[]): ament_flake8's own configuration over the working directory. Here
the configuration is setup.cfg's [flake8] (ament's choices at ruff.toml's 120 columns) and the folders are
named, because a checkout also holds build/ and .venv/, which a colcon source space does not.
"""
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    main_with_errors = pytest.importorskip('ament_flake8.main').main_with_errors
    rc, errors = main_with_errors(argv=['--config', str(ROOT / 'setup.cfg'), str(ROOT / 'rubber_rig'),
                                        str(ROOT / 'test'), str(ROOT / 'benchmarks'), str(ROOT / 'launch'),
                                        str(ROOT / 'setup.py')])
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
