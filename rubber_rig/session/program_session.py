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

"""ProgramSession: one test program on the setpoint stream a rig driver granted, from the grant to its end.

The excitation node (setpoints as ROS messages, the grant from the driver's open_stream service) and
:func:`.run.run_program` (an in-process RigDriver) both run a program through it, so the stream's rules are
written once: the setpoints are generated from the sample index and kept ``lead`` samples ahead of the sample the
rig plays (the latest measured one, or where the rig's pace has taken it since, on the caller's clock: rig_pace);
a hold keeps the stream (the driver holds the rig) and a resume on a new grant continues the
held block with the full cycles it had not run, counted from where the rig left the program (found in the applied
command measured after the hold: the rig runs on through what was streamed ahead until the hold reaches it); the
program has ended once its last setpoint was generated and measured. The session also carries the program's
detectors (what they judge, since when they were blind). Time is the sample index and the caller's `now`: nothing
here reads a clock.
"""
from __future__ import annotations

from typing import Callable, Iterator, Optional

import numpy as np

from ..excitation.detectors import Event, Monitor, blind_for, cycle_of
from ..excitation.runner import ProgramRunner
from ..excitation.streamer import SetpointChunk, SetpointStreamer
from .rig_pace import RigPace

#: applied command within this of the setpoint handed on [m]: the rig ran the program's sample (the feedback frames
#: carry the command in 0.1 um steps; run_program's fault split uses the same bound)
FOLLOW_TOLERANCE = 1.5e-7

#: [s] how far ahead of the sample the rig plays (ProgramSession.ahead_of) a program is streamed by default (the
#: excitation's lead_time): the queue rides out a stall of its producer of lead - the driver's stream_timeout
#: (0.15 s) - one stream period - the setpoints' way to the driver; a busy computer delays an executor 0.3-0.8 s,
#: and 1.0 s rides out 0.8 s (issue 34 item 4). The price is amplitude-loop latency (a 30 Hz block of 40 cycles as
#: a program's first ends 2.7 % short, 0.0 % at 0.5 s, 1.3 % at 0.8 s: benchmarks/bench_scenario.py --lead)
LEAD_TIME = 1.0

#: publish(first_sequence, displacement [m], block_index, end_of_stream): how a session hands setpoints on
Publish = Callable[[int, object, int, bool], None]


class ProgramSession:
    """A ProgramRunner on a granted stream (``grant``: stream_id, first_sequence, position [m]), streamed
    ``lead`` samples ahead of the measurement in chunks of ``chunk`` samples; ``detectors`` (DetectorSpecs, or
    None for none) judge its cycles and end-of-test triggers.
    """

    def __init__(self, runner: ProgramRunner, grant, lead: int, chunk: int, detectors: Optional[list] = None):
        self.runner = runner
        self.lead, self.chunk = int(lead), int(chunk)
        self.monitor = Monitor(detectors) if detectors is not None else None
        self.end_sequence: Optional[int] = None   # sequence after the last setpoint of the finished runner
        self.held = False                 # the driver holds the stream; resume() opens it on a new grant
        self.held_at: Optional[int] = None   # sequence after the last sample measured before the hold
        self.left_at: Optional[int] = None   # sequence after the last sample the rig ran on the program (held)
        self._left_known = False          # left_at is where the applied command left the program (not a bound)
        self._sent: list = []             # SetpointChunks handed on and not yet measured: (first, setpoints)
        self.elapsed_samples = 0          # program samples measured (rig time of the program, holds excluded)
        self.last_cycle_end = grant.first_sequence   # end of the latest judged cycle (detectors' blindness)
        self.pace = RigPace(runner.fs)    # the sample the rig plays now, on the owner's clock
        self._open(grant)

    @classmethod
    def on_grant(cls, program, sample_rate: float, limits, grant, lead: int, chunk: int,
                 amplitude_control: bool = False, compensation_memory: bool = True,
                 detectors: Optional[list] = None) -> 'ProgramSession':
        """A session whose runner starts at the grant: from the position [m] and velocity [m/s] the rig holds
        (an approach ramp leads to the program's start). The program must have been checked against ``limits``
        before the stream was asked for (from the grant on, every moment counts against the driver); a
        ValueError here means it cannot start from where the rig is.
        """
        runner = ProgramRunner(program, sample_rate, limits, amplitude_control, start_sequence=grant.first_sequence,
                               compensation_memory=compensation_memory, start_position=grant.position,
                               start_velocity=grant.velocity, check_program=False)
        return cls(runner, grant, lead, chunk, detectors)

    def describe(self) -> str:
        """One line for the log: the program, its stream and where the rig was when it was granted."""
        p = self.runner.program
        return (f"program '{p.name}': {len(p.blocks)} blocks, {p.duration(self.sample_rate):.1f} s, stream "
                f'{self.stream_id} from sample {self.start_sequence}, rig at {self.start_position * 1e3:.4f} mm')

    def _open(self, grant) -> None:
        self.streamer = SetpointStreamer(self.runner, self.lead, self.chunk)
        self.stream_id, self.held = grant.stream_id, False
        self.start_sequence, self.start_position = grant.first_sequence, grant.position
        self.pace.reset()
        # samples of an earlier rig (a restarted driver counts from 0) do not count
        self.next_sample: Optional[int] = None   # sequence after the latest measured sample of this stream

    # -- the measurement ----------------------------------------------------------------------------------------
    @property
    def sample_rate(self) -> float:
        return self.runner.fs

    @property
    def elapsed(self) -> float:
        """Rig time the program has been measured for [s] (holds excluded)."""
        return self.elapsed_samples / self.sample_rate

    def before_stream(self, first_sequence: int, n: int) -> bool:
        """A batch of ``n`` samples from ``first_sequence`` lies wholly before this stream (not the program's)."""
        return first_sequence + n <= self.start_sequence

    def measured(self, first_sequence: int, displacement, setpoint=None, now: Optional[float] = None,
                 stamp: Optional[float] = None) -> list[Event]:
        """A batch of measured samples [m] of this stream: to the amplitude control (not while held) and to the
        end-of-test triggers. Returns the detector events the batch trips. now [s]: when it arrived on the owner's
        clock, stamp [s]: when its last sample was measured (the rig's pace, see ``ahead_of``; None: not known).

        setpoint: the command [m] the rig applied to each sample (RigSampleBatch.setpoint), shape (n,). While held
        it tells where the rig left the program (its hold ramp's first sample, see ``left_at``); without it the
        hold counts from the last sample measured before it.
        """
        n = len(displacement)
        self.next_sample = first_sequence + n
        if now is not None and n:
            self.pace.observe(self.next_sample, now, stamp)
        if self.held:
            if n and setpoint is not None and len(setpoint) == n:
                ran = self._follow(first_sequence, np.asarray(setpoint, dtype=float))
                if ran:   # program samples the rig ran after the hold was asked for: they finish a measured cycle
                    self.runner.feed_measurement(ran[0], np.asarray(displacement, dtype=float)[
                        ran[0] - first_sequence:ran[1] - first_sequence])
            return []
        if not n:
            return []
        self._forget_sent(first_sequence + n)
        self.runner.feed_measurement(first_sequence, np.asarray(displacement, dtype=float))
        self.elapsed_samples += n
        if self.monitor is None:
            return []
        block, block_cycles, program_cycles = self.runner.where.cycles_done(self.next_sample - 1)
        if block < 0:
            return []
        return self.monitor.on_progress(block, block_cycles, program_cycles, self.elapsed, self.next_sample)

    @property
    def measured_sequence(self) -> int:
        """The sequence the stream is kept ``lead`` ahead of: after the latest measured sample, or its start."""
        return self.start_sequence if self.next_sample is None else max(self.next_sample, self.start_sequence)

    @property
    def measured_to_end(self) -> bool:
        """Every setpoint of the finished program has been measured: the block summaries are complete."""
        if self.end_sequence is None:
            return False
        if self.end_sequence <= self.start_sequence:
            return True                    # resumed after the rig had run the whole program: nothing to measure
        return self.next_sample is not None and self.next_sample >= self.end_sequence

    def ahead_of(self, now: Optional[float] = None) -> int:
        """The sequence the stream is kept ``lead`` ahead of: the sample the rig plays at `now` [s] on the owner's
        clock (rig_pace.RigPace, from when the sample batches arrived) where that is past the latest measured one,
        else measured_sequence (now None, or no pace known yet). At most ``lead`` past the measurement: a rig that
        stopped keeping its pace (it faults or holds) costs at most one lead of latency.

        Streaming ahead of the measurement alone counted the sample path's lag against the rig's reserve: on a busy
        computer the samples arrive late just when the excitation stalls (issue 34 item 4).
        """
        measured = self.measured_sequence
        playing = None if now is None else self.pace.playing(now)
        return measured if playing is None else max(measured, min(playing, measured + self.lead))

    def view(self, now: float) -> str:
        """What this owner knew at `now` [s], for the line that says why a program stopped: how far it streamed,
        how far the rig was measured, where the pace put the rig and how old the latest sample batch was. A stream
        lost with the latest batch fresh and the stream short of ``lead`` points at this owner's samples or
        scheduling; one lost with the batches stale points at the sample path.
        """
        playing, last = self.pace.playing(now), self.pace.last_arrival
        return (f'streamed to sample {self.runner.sequence}, measured to {self.measured_sequence}, '
                f"rig playing {'unknown' if playing is None else playing}, latest sample batch "
                f"{'never' if last is None else f'{now - last:.3f} s ago'}")

    # -- the setpoints ------------------------------------------------------------------------------------------
    def due(self, measured: Optional[int] = None) -> Iterator[SetpointChunk]:
        """The chunks that bring the stream ``lead`` ahead of ``measured`` (default: measured_sequence; see
        ``ahead_of``); a generator, see SetpointStreamer.due.
        """
        for chunk in self.streamer.due(self.measured_sequence if measured is None else measured):
            if chunk.displacement.size:
                self._sent.append((chunk.first_sequence, chunk.displacement))
            yield chunk

    def _forget_sent(self, measured_to: int) -> None:
        """Drop the chunks measured completely (below ``measured_to``): a hold looks only at what is ahead."""
        keep = 0
        while keep < len(self._sent) and self._sent[keep][0] + self._sent[keep][1].size <= measured_to:
            keep += 1
        if keep:
            del self._sent[:keep]

    def _sent_setpoint(self, sequence: int) -> Optional[float]:
        for first, x in self._sent:
            if first <= sequence < first + x.size:
                return float(x[sequence - first])
        return None

    def _follow(self, first_sequence: int, applied: np.ndarray) -> Optional[tuple[int, int]]:
        """Held: move ``left_at`` over the samples (contiguous with it) whose applied command is the setpoint this
        session handed on, to the first one that is not (the hold ramp began there; the frames carry the
        command to 0.1 um) or that was never sent. A gap in the measurement stops it (a lower bound: the cycles
        it may miss are run again, never skipped). Returns the sequences (start, end) it moved over, or None.
        """
        if self._left_known or first_sequence > self.left_at:
            self._left_known = self._left_known or first_sequence > self.left_at
            return None
        start = self.left_at
        for i in range(self.left_at - first_sequence, applied.size):
            sent = self._sent_setpoint(first_sequence + i)
            if sent is None or abs(applied[i] - sent) > FOLLOW_TOLERANCE:
                self._left_known = True
                break
            self.left_at = first_sequence + i + 1
            self.elapsed_samples += 1          # the rig ran this program sample after the hold was asked for
        return (start, self.left_at) if self.left_at > start else None

    def stream(self, publish: Publish, now: Optional[float] = None) -> None:
        """Hand on what is due (``lead`` ahead of ``ahead_of(now)``, now [s] on the owner's clock); the program's
        end once (an empty batch if its last setpoints went out before); with nothing due, an empty keep-alive
        batch (the driver's stream timeout watches for one).
        """
        r = self.runner
        sent = False
        for chunk in self.due(self.ahead_of(now)):
            publish(chunk.first_sequence, chunk.displacement, chunk.block, chunk.end)
            sent = True
        if r.finished and self.end_sequence is None:
            self.end_sequence = r.sequence
            if not sent:
                publish(r.sequence, [], -1, True)
        elif not sent and not r.finished:
            publish(r.sequence, [], r.block_index if r.state == 'running' else -1, False)

    # -- hold and resume ---------------------------------------------------------------------------------------
    def why_not_hold(self) -> str:
        """'' when the program can hold now, else why not: it runs, approaches its start, or its last setpoints
        were generated but not yet all measured (the rig still runs what was streamed ahead).
        """
        r = self.runner
        if self.held:
            return 'cannot hold: the program is held'
        if r.aborted or r.state not in ('running', 'approaching', 'finished'):
            return f'cannot hold: the program is {r.state}'
        if r.finished and self.measured_to_end:
            return 'cannot hold: the program has ended'
        return ''

    def hold(self) -> None:
        """Hold at the block mean (runner.hold_target, what the driver is asked to hold the rig at)."""
        self.runner.hold()
        self.held, self.held_at = True, self.measured_sequence
        self.left_at, self._left_known = self.held_at, False

    def resume(self, grant) -> None:
        """Continue on the stream of a new grant from where the rig left the program (``left_at``): the block it
        was in, with the full cycles that block had not finished (ProgramRunner.resume_at).
        """
        self._open(grant)
        self.runner.resume_at(grant.first_sequence, grant.position, measured_sequence=self.left_at)
        self._sent.clear()
        # generated anew from the block the rig was in: the end is where the resumed runner finishes
        self.end_sequence = grant.first_sequence if self.runner.finished else None
        self.last_cycle_end = grant.first_sequence     # the hold is not blindness
        if self.monitor is not None:
            self.monitor.rearm()

    def describe_resume(self) -> str:
        """One line for the log after resume(): where the rig had left the program and what runs now."""
        r = self.runner
        if r.finished:
            return f'resumed after the rig had run the whole program (it left it at sample {self.left_at})'
        b = r.block_index
        blk = r.program.blocks[b]
        done = r.where.cycles_before.get(b, 0)
        owed = f', {blk.cycles} full cycles still owed of {blk.cycles + done}' if blk.periodic else ''
        return (f"resumed block {b} '{blk.name}' on stream {self.stream_id} from sample {self.start_sequence}: the "
                f'rig left the program at sample {self.left_at} ({self.left_at - self.held_at} samples after the '
                f'last one measured when the hold was asked for){owed}')

    # -- detectors -------------------------------------------------------------------------------------------------
    def judge_cycle(self, start: int, end: int, amplitude: float, peak_amplitude: float, mean: float,
                    measured: dict, model: dict, residual_rms: float) -> list[Event]:
        """The detector events of the measured cycle of samples start..end-1 (none outside the program's
        periodic blocks: an approach or hold ramp, another stream's cycle).

        A cycle that began before this stream (a resumed program's: the element model's cycle runs from before the
        hold, through the hold ramp and the rest at the block mean, into the resumed block) is not the program's:
        its flat stretch looked like a saturated load cell to the detectors.
        """
        if self.held or self.monitor is None or start < self.start_sequence:
            return []
        cycle = cycle_of(self.runner, start, end, amplitude, peak_amplitude, mean, measured, model, residual_rms,
                         self.elapsed)
        if cycle is None:
            return []
        self.last_cycle_end = max(self.last_cycle_end, end)
        return self.monitor.on_cycle(cycle)

    def detectors_blind(self, sample_rate: float) -> float:
        """Rig time [s] a periodic block has run with its cycle detectors not judging (0: they are)."""
        if self.held or self.monitor is None or not self.monitor.needs_cycles or self.next_sample is None:
            return 0.0
        return blind_for(self.runner, self.next_sample - 1, self.last_cycle_end, sample_rate)
