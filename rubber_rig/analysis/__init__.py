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

"""Signal analysis of force-displacement records (pure numpy; never imports rclpy).

* :func:`harmonic_properties`: first-harmonic K_dyn and loss angle, loop energy, D (seed 000 Eq. 3),
  C_eq (Eq. 27) over whole cycles.
* :class:`CycleCutter`, :func:`cut_cycles`: the one cycle cut (upward mean crossings with hysteresis), streaming
  or over a whole array; :class:`CycleDetector`: streaming per-cycle metrics from chunks of (x, force).
"""
from .cycles import Cycle, CycleCutter, CycleDetector, cut_cycles
from .harmonic import HarmonicProperties, estimate_frequency, harmonic_properties

__all__ = ['Cycle', 'CycleCutter', 'CycleDetector', 'HarmonicProperties', 'cut_cycles', 'estimate_frequency',
           'harmonic_properties']
