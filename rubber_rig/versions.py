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
"""Which version of a third-party package this code was checked against, and a warning when another is installed.

The compatibility modules (recording/mcap_compat.py, nodes/rclpy_compat.py) use private parts of a package; a
:class:`CheckedVersion` each says which release that was checked on and warns once at import when the installed
major.minor differs (the private names may have moved).
"""
from __future__ import annotations

import importlib.metadata
import warnings
from dataclasses import dataclass


def version_matches(installed: str, checked: str) -> bool:
    """True when ``installed`` has the major.minor of ``checked``."""
    return installed.split('.')[:2] == checked.split('.')[:2]


@dataclass(frozen=True)
class CheckedVersion:
    """``package`` (distribution name) as checked at version ``checked`` by the module ``where``."""

    package: str
    checked: str
    where: str

    def installed(self) -> str:
        """The installed version ('' if its metadata cannot be found)."""
        try:
            return importlib.metadata.version(self.package)
        except importlib.metadata.PackageNotFoundError:
            return ''

    def matches(self, installed: str) -> bool:
        return version_matches(installed, self.checked)

    def check(self, installed: str | None = None) -> bool:
        """Warn (RuntimeWarning) unless the installed version has the checked major.minor; True when it has."""
        installed = self.installed() if installed is None else installed
        if self.matches(installed):
            return True
        warnings.warn(f'{self.package} {installed or "(version unknown)"} is installed; rubber_rig uses private '
                      f'parts of it checked against {self.checked} ({self.where})', RuntimeWarning, stacklevel=2)
        return False
