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

"""What the scenario tests share (test_scenario*.py): a short durability program and how an outcome is judged from
the applied command alone, independent of the runner's bookkeeping.
"""
import numpy as np

from rubber_rig.excitation.program import Program
from rubber_rig.rig.config import RigConfig

FS = 1000.0
# 60 cycles of 1 mm at 10 Hz (2 taper cycles each end), then a short second block: 8.2 s of program
DURABILITY = Program.from_dict({
    'name': 'durability_short', 'defaults': {'taper_cycles': 2, 'mean': 0.0},
    'blocks': [{'name': 'durability', 'waveform': 'sine', 'amplitude': '1 mm', 'frequency': '10 Hz', 'cycles': 60},
               {'name': 'after', 'waveform': 'sine', 'amplitude': '0.5 mm', 'frequency': '5 Hz', 'cycles': 5}]})
STREAM_TIMEOUT = RigConfig().stream_timeout
STREAM_PERIOD = 0.04


def full_cycles(outcome, frequency=10.0, amplitude=1e-3):
    """Full-amplitude cycles the rig ran, counted from the applied command alone (independent of the runner's
    bookkeeping): periods between upward zero crossings of contiguous samples that last 1/frequency (+-2
    samples) and reach `amplitude` within 1 %.
    """
    u, seq = outcome.setpoint, outcome.sequence
    up = np.flatnonzero((u[:-1] < 0) & (u[1:] >= 0)) + 1
    n = 0
    for a, b in zip(up[:-1], up[1:], strict=True):
        contiguous = np.all(np.diff(seq[a:b + 1]) == 1)
        full = (u[a:b].max() - u[a:b].min()) / 2 > 0.99 * amplitude
        if contiguous and abs((b - a) - FS / frequency) <= 2 and full:
            n += 1
    return n


def at_rest_inside_limits(outcome, limits):
    return (outcome.final_position == 0.0 and limits.displacement_min <= outcome.setpoint.min()
            and outcome.setpoint.max() <= limits.displacement_max)
