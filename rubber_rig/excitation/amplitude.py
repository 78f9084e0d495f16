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

"""Per-cycle amplitude measurement and the amplitude-control outer loop of one block.

A real actuator attenuates and delays the command at higher frequencies. The loop measures every
full-amplitude cycle of the displacement, estimates the plant gain from the command gain that was in force
during exactly that cycle (so measurement latency cannot cause over-correction), and sets the command
amplitude gain and mean offset for the following cycles, like peak-valley / amplitude-phase compensation.
A block starts from gain 1 and offset 0, or from what the run's compensation memory (compensation.py) learned
in earlier blocks; what this block learns (learned()) goes back into that memory.
"""
import math

import numpy as np

from .waveform_types import TYPES
from .waveforms import smoothstep

GAIN_MIN, GAIN_MAX = 0.5, 2.0


def _clamp_gain(gain: float) -> float:
    """Gain limited to GAIN_MIN..GAIN_MAX."""
    return min(max(gain, GAIN_MIN), GAIN_MAX)


def fit_cycle(waveform: str, phase: np.ndarray, x: np.ndarray):
    """Amplitude [m] and mean [m] of one measured cycle, read as its waveform's registry entry says
    (WaveformType.fit_cycle: a least-squares sine fit for sine-like waveforms, half the peak-valley range for a
    triangle or square, the peak-valley range above the valley for a haversine's one-sided pulses).
    """
    return TYPES[waveform].fit_cycle(phase, x)


class BlockLoop:
    """Cycle bookkeeping of one run of one periodic block: command gain per cycle, measured cycles.

    Gain changes are blended over one whole cycle with a raised cosine, so the command never steps.
    """

    def __init__(self, block, sample_rate: float, limits, control: bool):
        # waveforms whose amplitude one gain cannot set (a multisine's lines attenuate differently) run open loop
        self.block, self.fs, self.limits = block, sample_rate, limits
        self.control = control and block.type.controlled
        self.gain, self.offset = 1.0, 0.0           # wanted for cycles not yet generated
        self._committed = {}                        # cycle -> (g0, g1, o0, o1, samples generated)
        self._pending = {}                          # cycle -> ([phase arrays], [x arrays])
        self.cycles = []                            # measured steady cycles: (cycle, amplitude, mean, gain)
        self.estimates = []                         # control: (cycle, needed gain, needed offset) per clean cycle
        self.initial = (1.0, 0.0)                   # (gain, offset) the block started with
        total = block.total_cycles
        self._steady = (block.taper_cycles, total - block.taper_cycles)
        # peak velocity per metre of amplitude, to cap the gain under velocity_max
        self._unit_v = block.type.velocity_per_metre(block)

    def start_from(self, gain: float, offset: float) -> None:
        """Start the block's command at `gain` and mean `offset` [m] (e.g. from the run's compensation memory)
        instead of 1 and 0; the gain is capped like every correction. Call before the first command().
        """
        if self._committed:
            raise RuntimeError('start_from() after the block has started')
        self.offset = float(offset)
        self.gain = self._cap(float(gain), self.offset)
        self.initial = (self.gain, self.offset)

    # ---- command side
    def command(self, phase: np.ndarray):
        """Gain and mean offset arrays for the samples at `phase` [cycles] about to be generated."""
        c = np.floor(phase).astype(np.int64)
        uniq, inv, counts = np.unique(c, return_inverse=True, return_counts=True)
        g0 = np.empty(uniq.size)
        g1, o0, o1 = np.empty_like(g0), np.empty_like(g0), np.empty_like(g0)
        for j, cc in enumerate(uniq):
            cc = int(cc)
            if cc not in self._committed:
                prev = self._committed.get(cc - 1)
                start_g, start_o = (prev[1], prev[3]) if prev else (self.gain, self.offset)
                self._committed[cc] = [start_g, self.gain, start_o, self.offset, 0]
            rec = self._committed[cc]
            rec[4] += int(counts[j])
            g0[j], g1[j], o0[j], o1[j] = rec[:4]
        s = smoothstep(phase - c)
        return g0[inv] + (g1 - g0)[inv] * s, o0[inv] + (o1 - o0)[inv] * s

    # ---- measurement side
    def feed(self, phase: np.ndarray, x: np.ndarray):
        """Add measured displacement x [m] at commanded phases; finish every cycle a later sample shows complete."""
        c = np.floor(phase).astype(np.int64)
        first, last = int(c.min()), int(c.max())
        if first == last:       # the samples lie within one cycle (most batches): no sort and no selection
            lst = self._pending.setdefault(first, ([], []))
            lst[0].append(np.array(phase))
            lst[1].append(np.array(x))
        else:
            for cc in np.unique(c):
                sel = c == cc
                lst = self._pending.setdefault(int(cc), ([], []))
                lst[0].append(phase[sel])
                lst[1].append(x[sel])
        for cc in sorted(k for k in self._pending if k < last):
            self._finish(cc)

    def flush(self):
        """Finish all pending cycles (the block has been fully measured)."""
        for cc in sorted(self._pending):
            self._finish(cc)

    def _finish(self, cc: int):
        ph, xs = self._pending.pop(cc)
        phase, x = np.concatenate(ph), np.concatenate(xs)
        rec = self._committed.get(cc)
        if rec is None or not (self._steady[0] - 1e-9 <= cc and cc + 1 <= self._steady[1] + 1e-9):
            return
        if x.size < max(4, 0.8 * rec[4]):   # too many samples lost to judge this cycle
            return
        amp, mean = fit_cycle(self.block.waveform, phase, x)
        g_used = 0.5 * (rec[0] + rec[1])
        self.cycles.append((cc, amp, mean, g_used))
        if self.control and rec[0] == rec[1] and rec[2] == rec[3] and amp > 0:
            plant = amp / (g_used * self.block.amplitude)
            self.offset = rec[2] - (mean - self.block.mean)
            self.gain = self._cap(1.0 / plant, self.offset)
            self.estimates.append((cc, _clamp_gain(1.0 / plant), self.offset))

    def _cap(self, gain: float, offset: float) -> float:
        """Keep the corrected command inside the gain range and the displacement and velocity limits."""
        gain = _clamp_gain(gain)
        if self.limits is not None:
            a = self.block.amplitude
            centre = self.block.mean + offset
            room = min(self.limits.displacement_max - centre, centre - self.limits.displacement_min)
            gain = min(gain, max(room, 0.0) / a)
            gain = min(gain, 0.95 * self.limits.velocity_max / (self._unit_v * a))
        return gain

    def learned(self):
        """(gain, offset [m]) the block needs - 1 / plant gain and the mean correction - averaged over the last
        half of the cycles judged so far (uncapped by the limits), or None before the first.
        """
        if not self.estimates:
            return None
        tail = self.estimates[len(self.estimates) // 2:]
        return float(np.mean([e[1] for e in tail])), float(np.mean([e[2] for e in tail]))

    # ---- reporting
    def achieved(self):
        """(amplitude, mean) [m] averaged over the last half of the measured steady cycles, or (nan, nan)."""
        if not self.cycles:
            return math.nan, math.nan
        tail = self.cycles[len(self.cycles) // 2:]
        return float(np.mean([c[1] for c in tail])), float(np.mean([c[2] for c in tail]))

    def last_amplitude(self) -> float:
        """Amplitude [m] of the last measured steady cycle (nan before the first)."""
        return self.cycles[-1][1] if self.cycles else math.nan
