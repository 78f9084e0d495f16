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

"""A dependency-free progress bar on stderr for long fits (redrawn in place, at most ~10 times/s)."""
from __future__ import annotations

import sys
import time


class ProgressBar:
    def __init__(self, stream=None, width=30, enabled=True):
        self.stream = stream or sys.stderr
        self.width = width
        self.enabled = enabled
        self._last = 0.0
        self._t0 = time.monotonic()
        self._shown = False

    def __call__(self, fraction: float, what: str = ''):
        if not self.enabled:
            return
        now = time.monotonic()
        if fraction < 1.0 and now - self._last < 0.1:
            return
        self._last = now
        fraction = min(max(float(fraction), 0.0), 1.0)
        filled = int(round(fraction * self.width))
        bar = '#' * filled + '-' * (self.width - filled)
        self.stream.write(f'\r[{bar}] {100 * fraction:5.1f}% {now - self._t0:6.1f}s {what[:40]:<40}')
        self.stream.flush()
        self._shown = True

    def close(self):
        if self.enabled and self._shown:
            self.stream.write('\n')
            self.stream.flush()
