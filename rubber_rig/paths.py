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

"""Where the package's shipped files are: a checkout, a colcon install or a pip install.

``config/`` (rig and node YAML, the Foxglove layout) sits next to the package in a checkout (an editable
install) and in ``share/rubber_rig/config`` of an install prefix: colcon's (found through
AMENT_PREFIX_PATH, as ament_index does) or pip's (``data_files`` of setup.py, under ``sys.prefix``).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

PACKAGE = 'rubber_rig'
_CHECKOUT = Path(__file__).resolve().parents[1]


def config_dirs() -> list[Path]:
    """Candidate config directories, most specific first (a checkout before any install prefix)."""
    dirs = []
    if (_CHECKOUT / 'package.xml').exists():
        dirs.append(_CHECKOUT / 'config')
    prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p] + [sys.prefix]
    dirs += [Path(p) / 'share' / PACKAGE / 'config' for p in prefixes]
    return [d for i, d in enumerate(dirs) if d not in dirs[:i]]


def find_config(name: str | os.PathLike) -> Path:
    """A file given by path, or a shipped config file by name ('rig_sim.yaml'). Raises FileNotFoundError
    naming every place it looked.
    """
    path = Path(name)
    if path.exists():
        return path
    for d in config_dirs():
        if (d / name).exists():
            return d / name
    raise FileNotFoundError(f'config file {str(name)!r} not found (looked in ./, '
                            f'{", ".join(str(d) for d in config_dirs())})')


def config_file(name: str) -> Path:
    """Where a shipped config file is, or where it belongs when it does not exist yet (first config dir)."""
    dirs = config_dirs()
    return next((d / name for d in dirs if (d / name).exists()), dirs[0] / name)
