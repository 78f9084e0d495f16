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

"""Per-block measured properties: one code path for measurements and for time-domain model runs.

The numbers come from `rubber_rig.analysis.harmonic_properties` (first-harmonic K_dyn and loss
angle, loop-area energy, D, C_eq), so measured data and simulated model output are evaluated by
the same code. A window [start, stop) of whole cycles is passed with its closing sample (stop
inclusive), so that the loop closes on itself and all its cycles are used.
"""
from __future__ import annotations

import numpy as np

from rubber_rig.analysis import harmonic_properties as _shared


def window_properties(x, force, dt, start, stop, frequency) -> dict:
    """Properties of the whole cycles in samples [start, stop) of x and force (SI)."""
    end = min(stop + 1, len(x))
    return _shared(np.asarray(x[start:end], float), np.asarray(force[start:end], float), dt,
                   frequency=frequency).as_dict()
