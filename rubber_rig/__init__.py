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

"""rubber_rig: ROS 2 node suite for hardware-in-the-loop rubber-element test rigs.

The core (models, excitation, rig, recording, fitting) imports no rclpy; rubber_rig.nodes wires it to ROS 2.
"""
import re
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path


def _version() -> str:
    """The version package.xml states (the one source: setup.py reads it too); '+source' when run from a tree
    that is not installed.
    """
    try:
        return version('rubber_rig')
    except PackageNotFoundError:
        xml = (Path(__file__).resolve().parents[1] / 'package.xml').read_text(encoding='utf-8')
        return re.search(r'<version>\s*([^<\s]+)\s*</version>', xml).group(1) + '+source'


__version__ = _version()
