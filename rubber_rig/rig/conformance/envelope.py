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


"""What a conformance run may do and what it records of each sample: the operator's displacement envelope, and one
feedback sample as the run saw it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

PLAUSIBLE_VELOCITY = 1.0    # [m/s] default bound of a plausible rated velocity (Envelope.velocity_max)


@dataclass
class Envelope:
    """The displacement range [m] the operator allows the run to use: lower < 0 < upper; velocity_max [m/s]: the
    most a rated velocity stated by the controller may be to be taken as stated (CTRL-ID-3; above it the rating
    is implausible and CTRL-LIM-3 is tested at the envelope's own value, test_velocity).
    """

    lower: float
    upper: float
    velocity_max: float = PLAUSIBLE_VELOCITY

    def __post_init__(self):
        if not (math.isfinite(self.lower) and math.isfinite(self.upper) and self.lower < 0.0 < self.upper):
            raise ValueError(f'envelope {self.lower * 1e3:g}..{self.upper * 1e3:g} mm: it must contain the rest '
                             'position 0 mm (lower < 0 < upper)')

    @property
    def half(self) -> float:
        return min(-self.lower, self.upper)

    def test_velocity(self, fs: float, step_factor: float) -> float:
        """The rated velocity [m/s] CTRL-LIM-3 tests when the stated one is implausible: velocity_max, or less if
        a step of step_factor x it in one sample at fs [Hz] would not fit in 80 % of the envelope from rest.
        """
        return min(self.velocity_max, 0.8 * self.half * fs / step_factor)


@dataclass
class Sample:
    t: float
    seq: int
    x: float
    u: float
    state: str
    force: float = math.nan     # [N] measured force (CTRL-MEAS-1, CTRL-MEAS-2)
