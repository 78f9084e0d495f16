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

"""ProgramRunner: turns a program into setpoint chunks from the sample index, with amplitude control,
limit enforcement on every setpoint, hold/resume and the abort ramp.
"""
import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..safety import LimitError, Limits, SafeRamp, abort_ramp_velocity
from .amplitude import BlockLoop
from .compensation import CompensationMemory
from .limits import check_program as precheck
from .whereabouts import Whereabouts


@dataclass
class Progress:
    """Where the runner is (generation side) and the latest measured amplitude. SI units."""

    block_index: int
    block_name: str
    block_count: int
    cycle: int
    cycles_total: int
    target_amplitude: float
    achieved_amplitude: float
    fraction: float
    state: str


@dataclass
class BlockResult:
    """Result of one executed block (the fields of msg_defs/BlockSummary, which the nodes fill from it)."""

    block_index: int
    name: str
    waveform: str
    frequency: float
    target_amplitude: float
    achieved_amplitude: float
    mean: float
    achieved_mean: float
    cycles: int
    cycles_measured: int
    completed: bool
    message: str = ''


class ProgramRunner:
    """Generates the setpoints [m] of `program` at `sample_rate` [Hz], chunk by chunk, from the sample index.

    Setpoint sequence numbers start at start_sequence; measurements fed back with the same numbering drive the
    amplitude loop and the achieved-amplitude report. The program is checked against `limits` on construction
    (LimitError before anything is generated) unless check_program=False says the caller has just checked it
    against these limits; every generated chunk is checked again, and a violation turns
    into an abort ramp instead of a setpoint outside the limits.

    Open loop, the setpoints depend on the sample index only. With amplitude_control the command of a cycle also
    depends on which measured cycles had arrived when it was generated (it uses the gain in force during each
    measured cycle, so latency delays the correction but cannot make it overshoot).

    compensation_memory (with amplitude_control only): every periodic block starts from the command gain and
    mean offset that the blocks measured so far in this run learned (interpolated in log-frequency, see
    compensation.py) instead of from gain 1 - with setpoints streamed ahead of the measurement, a block's own
    correction may arrive only at its end. False: every block starts from gain 1 (the loop works per block).
    """

    def __init__(self, program, sample_rate: float, limits: Limits = None, amplitude_control: bool = False,
                 start_sequence: int = 0, compensation_memory: bool = True, start_position: float = None,
                 start_velocity: float = 0.0, check_program: bool = True):
        self.program, self.fs = program.copy(), float(sample_rate)   # resume_at shortens a block of its own copy
        self.limits = limits if limits is not None else Limits()
        if check_program:
            precheck(self.limits, program, self.fs)
        self.amplitude_control = amplitude_control
        # what the amplitude loop learned per block (gain, offset vs frequency): the next block's starting point
        self.compensation = CompensationMemory() if amplitude_control and compensation_memory else None
        self._starts = program.block_starts(self.fs)
        self._total = int(self._starts[-1])
        self._p = 0                                   # program sample index of the next setpoint
        self.sequence = int(start_sequence)           # sequence number of the next setpoint
        self.state = 'running'                        # approaching | running | holding | ramping_down | finished
        self.aborted, self.abort_reason = False, ''
        self._x = self._x_prev = program.initial_position
        self._ramp = None
        if start_position is not None and (abs(start_position - program.initial_position) > 1e-7 or start_velocity):
            # the rig is elsewhere (held, stopped after a lost stream): approach the program's start smoothly
            self.limits.check_setpoints([start_position], self.fs, where='approach from the rig position')
            self._x, self._x_prev = float(start_position), float(start_position) - start_velocity / self.fs
            self._start_ramp(program.initial_position)
            self.state = 'approaching'
        self._resume = False
        self._hold_block = None
        self._ramp_from = {}                          # ramp block index -> start override after a hold
        self._loops = {}                              # block index -> BlockLoop of its latest run
        self._learned = {}                            # block index -> (loop, estimates) last put in memory
        self.where = Whereabouts(self.program, self.fs)   # what was generated for which sample: where a sample is
        self._completed = set()
        self.cycles_measured_before = {}              # block index -> steady cycles measured before it
        self.last_block_index = np.empty(0, dtype=np.int32)

    # ---- state
    @property
    def finished(self) -> bool:
        """True when the program (or the abort ramp) has ended; further setpoints hold the last value."""
        return self.state == 'finished'

    @property
    def block_index(self) -> int:
        return min(int(np.searchsorted(self._starts, self._p, side='right')) - 1, len(self.program.blocks) - 1)

    def _velocity(self) -> float:
        return (self._x - self._x_prev) * self.fs

    # ---- commands
    def abort(self, reason: str = 'abort', target: float = None):
        """Stop the program: the following setpoints are a smooth ramp from the current setpoint and velocity to
        `target` [m] (default: the program's rest_position, normally zero), inside the limits.
        """
        if self.state == 'finished' and self.aborted:
            return
        target = self.program.rest_position if target is None else target
        self.aborted, self.abort_reason = True, reason
        self._start_ramp(self.limits.clamp_position(target))
        self.state = 'ramping_down'

    def hold(self):
        """Pause: ramp smoothly to the current block's mean (or stay where a ramp/hold block is) and wait. Also
        while approaching the start and after the last setpoint was generated (the rig may still run what was
        streamed ahead): resume_at() continues from where the rig left the program.
        """
        if self.state not in ('running', 'approaching') and not (self.state == 'finished' and not self.aborted):
            return
        b = self.block_index
        self._hold_block, self.state, self._resume = b, 'holding', False
        self._start_ramp(self.hold_target)

    @property
    def hold_target(self) -> float:
        """Where hold() goes [m]: the current block's mean (periodic) or the current setpoint."""
        blk = self.program.blocks[self.block_index]
        return blk.mean if blk.oscillating else self._x

    def resume_at(self, sequence: int, position: float, measured_sequence: int = None):
        """Continue after hold() on a new stream at `sequence`, approached smoothly from `position` [m] (where the
        rig holds) if that is not where the block starts.

        `measured_sequence`: the sample after the last one the rig ran on the program before the hold (where its
        hold ramp began, ProgramSession.left_at). The block the rig was in resumes: a periodic one with the full
        cycles it had not finished, counted on in cycles_before (the interrupted cycle runs again, with the taper
        in and out); a block run to its end is not run again; a hold, ramp or sweep block restarts. Without it
        (or before the program's first sample) the held block restarts with its taper.
        """
        if self.state != 'holding':
            return
        b, run = self._hold_block, None
        at = self.where.program_position(measured_sequence) if measured_sequence is not None else None
        if at is not None:
            b, run = at
        blk = self.program.blocks[b]
        if run is not None and run >= int(self._starts[b + 1] - self._starts[b]):
            self._completed.add(b)
            b, run = b + 1, None                       # the rig ran this block to its end
        elif run is not None and blk.periodic:
            done = int(math.floor(float(blk.phase(np.array(run / self.fs))) - blk.taper_cycles + 1e-9))
            done = min(max(done, 0), blk.cycles)
            if done >= blk.cycles:
                self._completed.add(b)                 # every full cycle ran: only the taper-out was cut short
                b = b + 1
            elif done:
                self.program.blocks[b] = dataclasses.replace(blk, cycles=blk.cycles - done)
                self.program._starts.clear()
                self._starts = self.program.block_starts(self.fs)
                self._total = int(self._starts[-1])
                self.where.cycles_before[b] = self.where.cycles_before.get(b, 0) + done
        for later in range(b, len(self.program.blocks)):
            self._completed.discard(later)             # generated before the hold, not run: they run again
        self.sequence = int(sequence)
        self._x = self._x_prev = float(position)
        if b >= len(self.program.blocks):              # the rig had run the whole program
            self._p, self.state, self._ramp, self._resume = self._total, 'finished', None, False
            return
        self._hold_block = b
        self._p = int(self._starts[b])
        target = self.hold_target
        self._restart(b)
        if abs(position - target) > 1e-7:
            self._start_ramp(target)
            self.state = 'approaching'

    def resume(self):
        """Continue after hold(): the held block restarts from its beginning (with its taper) once the hold
        ramp has settled.
        """
        if self.state == 'holding':
            self._resume = True

    def _start_ramp(self, target):
        lim = self.limits
        self._ramp = SafeRamp(self._x, self._velocity(), target, self.fs,
                              velocity_max=abort_ramp_velocity(lim),
                              decel_max=lim.deceleration_max, lower=lim.displacement_min,
                              upper=lim.displacement_max)

    # ---- generation
    def next_setpoints(self, n: int) -> np.ndarray:
        """The next n setpoints [m], shape (n,); their sequence numbers are self.sequence .. + n - 1 (before the
        call). After the end the last value is held.
        """
        out = np.empty(int(n))
        blocks = np.full(int(n), -1, dtype=np.int32)
        i = 0
        while i < n:
            if self.state == 'running':
                if self._p >= self._total:
                    self.state = 'finished'
                    continue
                m, x, b = self._program_chunk(n - i)
                try:
                    self.limits.check_setpoints(x, self.fs, self._x,
                                                f"block {b} '{self.program.blocks[b].name}' setpoint")
                except LimitError as exc:
                    self._p += m
                    self.abort(str(exc))
                    continue
                out[i:i + m] = x
                blocks[i:i + m] = b
                self._record(self.sequence + i, m, b)
                self._p += m
                self._set_last(x)
                i += m
                if self._p >= self._total:
                    self.state = 'finished'
            elif self.state == 'approaching':
                k = n - i
                x = self._ramp.run(k) if not self._ramp.done else np.empty(0)
                j = int(np.argmax(x == self._ramp.target)) + 1 if self._ramp.done and x.size else x.size
                out[i:i + j] = x[:j]
                self._set_last(x[:j])
                i += j
                if self._ramp.done:
                    self.state, self._ramp = 'running', None
            elif self.state in ('ramping_down', 'holding'):
                if self._ramp.done and self.state == 'ramping_down':
                    self.state = 'finished'
                    continue
                if self._ramp.done and self._resume:
                    self._restart(self._hold_block)
                    continue
                k = n - i
                x = self._ramp.run(k)
                out[i:] = x
                self._set_last(x)
                i = n
                if self._ramp.done and self.state == 'ramping_down':
                    self.state = 'finished'
            else:
                out[i:] = self._x
                self._x_prev = self._x
                i = n
        self.sequence += int(n)
        self.last_block_index = blocks   # program block of each returned setpoint (-1: hold/abort ramp, end)
        return out

    def _set_last(self, x):
        if x.size >= 2:
            self._x_prev, self._x = float(x[-2]), float(x[-1])
        elif x.size == 1:
            self._x_prev, self._x = self._x, float(x[0])

    def _program_chunk(self, want):
        b = self.block_index
        blk = self.program.blocks[b]
        m = min(want, int(self._starts[b + 1]) - self._p)
        local = np.arange(self._p - self._starts[b], self._p - self._starts[b] + m)
        t = local / self.fs
        if blk.oscillating:
            loop = self._loops.get(b)
            if loop is None or local[0] == 0:   # first sample of a (re)started block: fresh cycle bookkeeping
                loop = self._loops[b] = BlockLoop(blk, self.fs, self.limits, self.amplitude_control)
                start = self.compensation.lookup(blk) if self.compensation is not None else None
                if start is not None:
                    loop.start_from(*start)
            phase = blk.phase(t)
            gain, offset = loop.command(phase)
            x = blk.evaluate_phase(phase, gain, offset)
        else:
            x = blk.evaluate(t, start_level=self._ramp_from.get(b))
        if local[-1] == int(self._starts[b + 1] - self._starts[b]) - 1:
            self._completed.add(b)
        return m, x, b

    def _restart(self, b):
        blk = self.program.blocks[b]
        if blk.type.family == 'ramp':
            self._ramp_from[b] = self._x
        loop = self._loops.pop(b, None)
        if loop is not None:
            self.cycles_measured_before[b] = self.cycles_measured_before.get(b, 0) + len(loop.cycles)
        self._p = int(self._starts[b])
        self.state, self._ramp, self._resume = 'running', None, False

    def _record(self, seq0, m, b):
        local0 = self._p - int(self._starts[b])
        self.where.record(seq0, m, b, local0, self._loops.get(b))

    # ---- measurement
    def feed_measurement(self, first_seq: int, displacement) -> None:
        """Measured displacement [m] for sequences first_seq .. + len - 1 (gaps allowed between calls).

        Drives the amplitude loop and the achieved-amplitude report; samples outside program blocks (ramps
        after abort) are ignored.
        """
        x = np.asarray(displacement, dtype=float)
        if x.size == 0:
            return
        s0, s1 = int(first_seq), int(first_seq) + x.size
        for seq0, seq1, b, local0, loop in self.where.overlapping(s0, s1):
            lo, hi = max(s0, seq0), min(s1, seq1)
            if lo < hi and loop is not None:
                t = (local0 + np.arange(lo - seq0, hi - seq0)) / self.fs
                loop.feed(self.program.blocks[b].phase(t), x[lo - s0:hi - s0])
            if loop is not None and s1 >= seq1 and self._generated_all(b, loop):
                loop.flush()   # the block's last cycle is complete only once generation has left the block
            if loop is not None and self.compensation is not None:
                self._learn(b, loop)

    def _learn(self, b, loop):
        """Put what `loop` (block b) learned so far into the compensation memory (once per new judged cycle)."""
        n = len(loop.estimates)
        seen = self._learned.get(b)
        if n and not (seen and seen[0] is loop and seen[1] == n):
            self._learned[b] = (loop, n)
            self.compensation.learn(b, self.program.blocks[b], *loop.learned())

    def _generated_all(self, b, loop):
        return b in self._completed and (self._loops.get(b) is not loop or self.block_index != b
                                         or self._p >= self._starts[b + 1])

    # ---- reporting
    @property
    def progress(self) -> Progress:
        """Progress of generation: block, cycle, target and last measured amplitude [m], fraction 0..1."""
        b = self.block_index
        blk = self.program.blocks[b]
        local = self._p - int(self._starts[b])
        cycle, total = 0, 0
        if blk.oscillating:
            total = int(math.floor(blk.total_cycles - 2 * blk.taper_cycles + 1e-9))
            phase = float(blk.phase(np.array(local / self.fs)))
            cycle = int(min(max(math.floor(phase - blk.taper_cycles) + 1, 0), total))
        loop = self._loops.get(b)
        achieved = loop.last_amplitude() if loop else math.nan
        frac = 1.0 if self.finished and not self.aborted else min(self._p / max(self._total, 1), 1.0)
        return Progress(b, blk.name, len(self.program.blocks), cycle, total, blk.amplitude, achieved, frac,
                        self.state)

    @property
    def block_summaries(self):
        """BlockResult for every block that has started, in program order."""
        out = []
        for b, blk in enumerate(self.program.blocks):
            if self._p <= self._starts[b] and b not in self._completed:
                continue
            loop = self._loops.get(b)
            amp, mean = loop.achieved() if loop else (math.nan, math.nan)
            done = b in self._completed and not (self.aborted and self._starts[b + 1] > self._p)
            msg = '' if done else (f'aborted: {self.abort_reason}' if self.aborted else 'running')
            # a resumed block runs the cycles it still owed: its summary counts the block's cycles, all of them
            measured = self.cycles_measured_before.get(b, 0) + (len(loop.cycles) if loop else 0)
            out.append(BlockResult(b, blk.name, blk.waveform, blk.frequency, blk.amplitude, amp, blk.mean, mean,
                                   blk.cycles + self.where.cycles_before.get(b, 0), measured, done, msg))
        return out
