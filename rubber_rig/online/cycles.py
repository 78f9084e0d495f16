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

"""Per-cycle metrics of measurement and model side by side (what the element_model node publishes as CycleMetrics).

Both forces (measured and model) belong to the measured displacement, so one CycleDetector cuts the cycles on x
and evaluates both force channels over exactly the same samples; the pairer maps detector sample indices back
to rig sequence numbers.

Why a restart at every program block: a cycle that spans two blocks (another frequency, amplitude or mean)
measures neither, and the detector's trigger levels come from the previous cycle - after a ramp to a new
preload (seed 004) the old mean lies outside the new motion and no cycle would ever be cut. Fed block by
block, the detector starts each block from its own data.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from rubber_rig.analysis import CycleDetector

# what a detector judges of each side of a cycle (msg_defs/CycleProperties carries the same fields)
PROPERTY_FIELDS = ('k_dyn', 'loss_angle', 'damping', 'c_eq', 'energy_harmonic', 'energy_loop', 'force_mean',
                   'force_amplitude')


def cycle_properties(m) -> dict:
    """{PROPERTY_FIELDS: value} (SI, NaN where missing) of one side of a cycle, from the harmonic analysis' fields
    (a mapping or an object). force_amplitude is half the force range: k_peak x half the displacement range.
    """
    def get(name):
        v = m.get(name) if isinstance(m, Mapping) else getattr(m, name, None)
        return float('nan') if v is None else float(v)
    out = {name: get(name) for name in PROPERTY_FIELDS[:-1]}
    out['force_amplitude'] = get('k_peak') * get('peak_amplitude')
    return out


@dataclass
class PairedCycle:
    index: int
    start_sequence: int
    end_sequence: int          # exclusive
    measured: dict             # HarmonicProperties fields (k_dyn, loss_angle, damping, c_eq, energy_*, ...)
    model: dict
    residual_rms: float = float('nan')   # RMS of measured - model force over the cycle [N]


class CyclePairer:
    """Cuts cycles of the measured displacement and pairs the measured and model properties of each."""

    def __init__(self, hysteresis: float = 0.2, min_amplitude: float = 0.0):
        self.hysteresis = hysteresis
        self.min_amplitude = min_amplitude   # [m] smaller "cycles" are noise (rig holding, taper ends)
        self._detector = None
        self._dt = None
        self._origin = None        # sequence number of the detector's sample index 0
        self._next = None
        self._block = None

    def feed(self, first_sequence: int, dt: float, x: np.ndarray, measured: np.ndarray,
             predicted: np.ndarray, block: int = -1) -> list[PairedCycle]:
        """Samples from ``first_sequence`` on, all of program block ``block`` (-1: unknown); finished cycles."""
        if self._detector is None or dt != self._dt or first_sequence != self._next or block != self._block:
            # first batch, new rate, a sequence gap or a new block: a cycle across it would be wrong -> restart
            self._detector = CycleDetector(dt, self.hysteresis, self.min_amplitude)
            self._dt, self._origin, self._block = dt, first_sequence, block
        self._next = first_sequence + len(x)
        out = []
        for c in self._detector.update(x, measured, predicted):
            m, p = c['channels']
            if m['amplitude'] < self.min_amplitude:
                continue
            out.append(PairedCycle(c['index'], self._origin + c['start'], self._origin + c['end'], m, p,
                                   c.get('rms_difference', float('nan'))))
        return out
