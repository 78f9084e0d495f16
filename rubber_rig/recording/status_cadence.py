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

"""When the recorder publishes its status (recorder_status): at once when what it says changed, and at least every
``period`` [s] otherwise (a program with require_recording calls a recorder gone whose status is recorder_timeout
old). ROS-free; ``now`` is the caller's clock [s].
"""
from __future__ import annotations

import math
from typing import Hashable, Optional


class StatusCadence:
    """Whether a status with the content ``key`` is due at ``now`` (see the module doc).

    Parameters
    ----------
    period : float
        [s] the longest time between two statuses.
    """

    def __init__(self, period: float):
        self.period = float(period)
        self.key: Optional[Hashable] = None     # what the latest published status said
        self.sent = -math.inf                   # [s] when it was published

    def due(self, key: Hashable, now: float, force: bool = False) -> bool:
        """True (and noted as published) when ``key`` differs from the latest status, ``period`` has passed since it,
        or ``force``.
        """
        if not force and key == self.key and now - self.sent < self.period:
            return False
        self.key, self.sent = key, now
        return True
