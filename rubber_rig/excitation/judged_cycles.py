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

"""Which cycle of a program a measured cycle is, as the detectors judge it, and when they go blind.

The element model measures cycles on the rig's samples without knowing the program; :func:`cycle_of` places
one in its block (or says it is not judged: an approach, a hold ramp, a waveform whose cycles are not judged)
and makes the :class:`Cycle` a detector sees; :func:`blind_for` says how long a periodic block has run with
no cycle judged (the element model's metrics are not arriving).
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class Cycle:
    """One measured cycle as a detector sees it (from msg_defs/CycleMetrics, SI).

    measured/model: {k_dyn, c_eq, loss_angle, force_mean, force_amplitude}. block: the program block; cycle:
    its full-amplitude cycle number counted across holds (1 = the first); steady: the cycle lies inside the
    block's full-amplitude part; target_amplitude/target_mean [m]; elapsed: program rig time at its end [s].
    """

    block: int
    cycle: int
    steady: bool
    amplitude: float
    mean: float
    measured: dict
    model: dict
    residual_rms: float
    target_amplitude: float = math.nan
    target_mean: float = math.nan
    elapsed: float = math.nan
    program_cycle: int = 0
    end_sequence: int = 0          # rig sample sequence after the cycle's last sample


def cycle_of(runner, start: int, end: int, amplitude: float, peak_amplitude: float, mean: float, measured: dict,
             model: dict, residual_rms: float, elapsed: float) -> Cycle | None:
    """The Cycle a detector judges for the measured cycle of samples start..end-1 of `runner`'s program (an
    excitation ProgramRunner), or None outside one periodic block (an approach or hold ramp, a foreign stream) or
    in one whose cycles are not judged (WaveformType.judged). Amplitude as WaveformType.cycle_amplitude reads it.
    """
    where = runner.where.cycle_position(start, end)
    blk = runner.program.blocks[where[0]] if where is not None else None
    if blk is None or not blk.type.judged:
        return None
    block, number, steady = where
    _, _, program_cycles = runner.where.cycles_done(end - 1)
    return Cycle(block, number, steady, blk.type.cycle_amplitude(amplitude, peak_amplitude), mean, measured, model,
                 residual_rms, blk.amplitude, blk.mean, elapsed, program_cycles, int(end))


BLIND_SECONDS, BLIND_CYCLES = 2.0, 5     # no cycle judged for this long (and this many cycles): detectors blind


def blind_for(runner, sequence: int, last_cycle_end: int, sample_rate: float) -> float:
    """Rig time [s] a periodic block has run at `sequence` with no measured cycle judged since `last_cycle_end`
    (the end sequence of the latest cycle metrics, or the program's first sample), when that is more than
    BLIND_SECONDS and BLIND_CYCLES cycles: the element model's cycle metrics are not arriving, so no cycle
    detector can trip. 0.0 otherwise (judging keeps up, or the rig is not in a periodic block).
    """
    located = runner.where.locate(sequence)
    if located is None:
        return 0.0
    block, phase = located
    blk = runner.program.blocks[block]
    if not blk.oscillating or not blk.type.judged:
        return 0.0
    f = max(blk.frequency, blk.frequency_end or 0.0, 1e-6)
    since = (sequence - last_cycle_end) / sample_rate
    in_block = phase / f
    if min(since, in_block) > max(BLIND_SECONDS, BLIND_CYCLES / f):
        return since
    return 0.0
