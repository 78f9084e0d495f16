"""Per-cycle metrics of measurement and model side by side (ROS-free glue of the element_model node).

Both streams share the measured displacement, so two CycleDetectors fed with the same x cut exactly the same
cycles; the pairer only matches them by index and maps detector sample indices back to rig sequence numbers.
Noise on x cannot make them disagree: the cut depends on x alone.

Why a restart at every program block: a cycle that spans two blocks (another frequency, amplitude or mean)
measures neither, and the detector's trigger levels come from the previous cycle - after a ramp to a new
preload (seed 004) the old mean lies outside the new motion and no cycle would ever be cut. Fed block by
block, the detector starts each block from its own data.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rubber_rig.analysis import CycleDetector


@dataclass
class PairedCycle:
    index: int
    start_sequence: int
    end_sequence: int          # exclusive
    measured: dict             # HarmonicProperties fields (k_dyn, loss_angle, damping, c_eq, energy_*, ...)
    model: dict


class CyclePairer:
    """Feeds measured and predicted force through two CycleDetectors and pairs their cycles."""

    def __init__(self, hysteresis: float = 0.2, min_amplitude: float = 0.0):
        self.hysteresis = hysteresis
        self.min_amplitude = min_amplitude   # [m] smaller "cycles" are noise (rig holding, taper ends)
        self._measured = self._model = None
        self._dt = None
        self._origin = None        # sequence number of the detectors' sample index 0
        self._next = None
        self._block = None

    def reset(self) -> None:
        self._measured = self._model = None

    def feed(self, first_sequence: int, dt: float, x: np.ndarray, measured: np.ndarray,
             predicted: np.ndarray, block: int = -1) -> list[PairedCycle]:
        """Samples from ``first_sequence`` on, all of program block ``block`` (-1: unknown); finished cycles."""
        if self._measured is None or dt != self._dt or first_sequence != self._next or block != self._block:
            # first batch, new rate, a sequence gap or a new block: a cycle across it would be wrong -> restart
            self._measured = CycleDetector(dt, self.hysteresis, self.min_amplitude)
            self._model = CycleDetector(dt, self.hysteresis, self.min_amplitude)
            self._dt, self._origin, self._block = dt, first_sequence, block
        self._next = first_sequence + len(x)
        out = []
        for m, p in zip(self._measured.update(x, measured), self._model.update(x, predicted)):
            if m['amplitude'] < self.min_amplitude:
                continue
            out.append(PairedCycle(m['index'], self._origin + m['start'], self._origin + m['end'], m, p))
        return out
