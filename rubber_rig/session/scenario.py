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

"""A scenario on simulated time: the suite's ROS-free core in one process, stepped on one clock, deterministically.

What runs, each the same code the nodes call:

* the simulated controller (rig.sim.SimController, paced on the scenario's clock: ``serve(now)``) and the host's
  RigDriver, on a simulated CAN segment with the configured bit timing (rig.can.simbus.BusMedium);
* the driver's admission of setpoint batches (rig.can.gate.StreamGate) and its owner watch
  (session.liveness.OwnerWatch: an owner that beat and fell silent for owner_timeout loses its stream);
* the excitation's program session (session.ProgramSession): setpoints generated from the sample index and
  streamed ``lead_time`` ahead of the sample the rig plays, every ``stream_period``, with a heartbeat every
  liveness.PERIOD; its detectors judge each cycle and their strongest action (hold, end) is taken as the
  excitation node takes it;
* the element model (online.OnlinePredictor) predicting every sample batch, and its cycle cutter
  (online.cutter.CycleCutter) pairing measured and predicted cycles block by block for the detectors.

Each component wakes on its own period, like a node's timer; between wake-ups the messages it would receive
wait in its inbox (a topic's queue). :meth:`Scenario.stall` makes a component miss its wake-ups for a while (an
executor stalled by a busy computer: its inbox is handled late, all at once) or for ever (a process frozen or
killed); ``freeze`` stops the controller. Nothing here reads the wall clock: the same seed gives the same samples,
events and outcome on any computer, however busy, and much faster than real time (benchmarks/bench_scenario.py).
What still needs the wall clock - DDS, processes, the executor itself - is the end-to-end tier's (test_nodes*.py).
"""
from __future__ import annotations

import math
from collections import deque
from typing import Optional

import numpy as np

from ..excitation.detector_specs import DEFAULTS, parse_detectors, with_defaults
from ..excitation.program import Program, load_program
from ..online import ModelChoice, OnlinePredictor, cycle_properties
from ..online.cutter import CycleCutter
from ..recording.writer import RecordingWriter
from ..rig.can.batcher import SampleBatcher
from ..rig.can.gate import StreamGate
from ..rig.can.stream import StreamRefused
from ..rig.stepped import SteppedRig
from .liveness import OWNER_TIMEOUT, PERIOD, Beat, OwnerWatch, Peers
from .program_session import LEAD_TIME, ProgramSession
from .program_watch import RigView, detector_action, why_rig_stopped
from .scenario_delays import PATHS, Link, Stall
from .scenario_outcome import Outcome, sample_batch_record, setpoint_batch_record

#: the names components are stalled by
COMPONENTS = ('excitation', 'driver', 'controller', 'element_model')
BATCH_PERIOD, MAX_BATCH_DELAY = 0.01, 0.1   # [s] rig_driver's sample batches (batch_size 0), max_batch_delay
MIN_CYCLE_AMPLITUDE = 5e-6      # [m] smallest cycle the element model pairs (its min_cycle_amplitude default)


class Scenario:
    """One program on a simulated rig, stepped on simulated time (see the module docstring).

    program: Program, YAML path or shipped name; rig: RigConfig settings over the defaults (paced, with bus timing;
    sim.seed sets the noise); lead_time [s], stream_period [s], batch_size [samples] as the excitation node's
    parameters; owner_timeout [s] as rig_driver's; poll_period [s] the driver's poll timer, the scenario's step;
    model the element model's choice (default: the simulated specimen's parameter set); detectors the
    DetectorSpecs (default: the program's own plus the excitation's defaults); record: an MCAP path the samples
    and setpoints of each program are written to as the recorder writes them, stamped with scenario time.
    """

    OWNER = '/scenario/excitation'

    def __init__(self, program, rig: Optional[dict] = None, *, lead_time: float = LEAD_TIME,
                 stream_period: float = 0.04, batch_size: int = 50, owner_timeout: float = OWNER_TIMEOUT,
                 poll_period: float = 0.002, amplitude_control: bool = False, model: Optional[ModelChoice] = None,
                 detectors: Optional[list] = None, record=None, start: float = 100.0):
        self.rig = SteppedRig(rig, step=poll_period, start=start)
        self.cfg = self.rig.cfg
        self.program = program if isinstance(program, Program) else load_program(program)
        self.fs = self.cfg.sample_rate
        self.lead, self.batch = math.ceil(lead_time * self.fs), int(batch_size)
        self.stream_period = float(stream_period)    # the excitation's timer (the driver polls every rig step)
        self.owner_timeout, self.amplitude_control = float(owner_timeout), amplitude_control
        clock = self.clock
        self.controller, self.driver = self.rig.controller, self.rig.driver
        self.gate = StreamGate(self.driver, clock=clock)
        self.batcher, self.samples_per_batch = SampleBatcher(clock=clock), max(1, round(BATCH_PERIOD * self.fs))
        self.peers = Peers(silent=owner_timeout, clock=clock)
        self.owner_watch = OwnerWatch(self.peers)
        self.stalls: list[Stall] = []
        self.holds: list = []           # [hold at, resume at, 'due' | 'held' | 'resumed' | refusal] [s]
        self.actions: list = []         # [at [s], action(scenario)] not yet taken
        self.refusals: list = []        # the gate's verdicts on foreign batches
        self.log: list[str] = []        # what the excitation said (hold, resume)
        self.predictor = OnlinePredictor(model or ModelChoice())
        self.cutter = CycleCutter(MIN_CYCLE_AMPLITUDE, clock=clock)
        self.detectors = detectors if detectors is not None else with_defaults(
            self.program.all_detectors(), parse_detectors(list(DEFAULTS), 'default_detectors'))
        self.events: list = []          # every detector event: (scenario time [s], Event)
        self.streamed: list = []        # (first sequence, setpoints) of every batch the excitation published
        self.session: Optional[ProgramSession] = None
        self.grant = None
        self.record, self.writer = record, None
        # the topics: what each component receives at its next wake-up
        self.samples = Link()           # sample blocks on their way to the excitation
        self.model_inbox = deque()      # sample blocks and setpoint batches on their way to the element model
        self.cycles = deque()           # the element model's cycles on their way to the excitation
        self.batches = Link()           # setpoint batches on their way to the driver
        self.measured = []              # every block the driver measured (what a recorder would record)
        self.ended, self.completed, self.started_at, self._measured_from = '', False, None, 0
        self._excitation_due = self.now
        self._next_beat = self.now

    @property
    def now(self) -> float:
        """Scenario time [s]: the rig's clock."""
        return self.rig.now

    def clock(self) -> float:
        return self.rig.now

    # -- what a test injects --------------------------------------------------------------------------------------
    def stall(self, component: str, at: float, duration: float = math.inf) -> 'Scenario':
        """`component` ('excitation', 'driver', 'controller') misses its wake-ups from `at` [s after the program's
        start] for `duration` [s] (default: for ever, a dead or frozen process). Returns self.
        """
        if component not in COMPONENTS:
            raise ValueError(f'no component {component!r}: one of {", ".join(COMPONENTS)}')
        self.stalls.append(Stall(float(at), float(duration), component=component))
        return self

    def hold(self, at: float, duration: float) -> 'Scenario':
        """The operator holds the program at `at` [s after its start] and resumes it `duration` [s] later, through
        the excitation's own hold path (excitation/hold true, then false). Returns self.
        """
        self.holds.append([float(at), float(at) + float(duration), 'due'])
        return self

    def at(self, t: float, action) -> 'Scenario':
        """Call ``action(scenario)`` once, `t` [s] after the program's start (an operator, another process on the
        domain, a parameter change): e.g. ``lambda sc: sc.driver.abort('operator')``. Returns self.
        """
        self.actions.append([float(t), action])
        return self

    def foreign(self, t: float, channel: str, source: str, displacement: float, n: int = 1,
                copy_stream: bool = True) -> 'Scenario':
        """`n` setpoint batches of 50 samples at `displacement` [m] from another process, `t` [s] after the start:
        on `channel` (the owner's command channel, or another one) under the sender name `source`, with the open
        stream's id and next sequence copied (copy_stream) or made up. The gate's verdicts go to ``self.refusals``.
        """
        def send(sc):           # what the setpoints topic shows anyone: the stream id and where the stream goes on
            first, x = sc.streamed[-1] if sc.streamed else (0, ())
            stream_id = sc.session.stream_id if copy_stream and sc.session is not None else 12345
            for _ in range(n):
                sc.refusals.append(sc.gate.offer(channel, source, first + len(x), np.full(50, displacement),
                                                 stream_id))
        return self.at(t, send)

    def wait(self, seconds: float) -> None:
        """Let `seconds` [s] of scenario time pass (between programs: an operator looking at the rig)."""
        self._advance_until(lambda: False, seconds, '')

    def delay(self, path: str, seconds: float, at: float = 0.0, duration: float = math.inf) -> 'Scenario':
        """Messages on `path` ('samples': driver to excitation, 'setpoints': excitation to driver) published from
        `at` [s after the program's start] for `duration` [s] arrive `seconds` [s] late (a loaded computer).
        """
        if path not in PATHS:
            raise ValueError(f'no path {path!r}: one of {", ".join(PATHS)}')
        (self.samples if path == 'samples' else self.batches).delay(seconds, at, duration)
        return self

    def _since_start(self) -> Optional[float]:
        return None if self.started_at is None else self.now - self.started_at

    def _stalled(self, component: str) -> bool:
        return component in self._stalled_now()

    def _stalled_now(self) -> set:
        """The components that miss their wake-ups now."""
        if self.started_at is None or not self.stalls:
            return set()
        t = self.now - self.started_at
        return {s.component for s in self.stalls if s.covers(t)}

    # -- running ----------------------------------------------------------------------------------------------------
    def run(self, timeout: float = None, program=None) -> Outcome:
        """Power up, open the stream, run the program until it ends (or `timeout` [s] of scenario time after the
        start: by default the program's duration plus 10 s) and until the rig is at rest; returns the Outcome.

        program: the next program on the same rig (after the first run): the operator resets the faults the
        last one left (rig_driver/reset) and it runs without the stalls, holds and actions of the first.
        """
        if program is not None:
            self.program = program if isinstance(program, Program) else load_program(program)
            self.stalls, self.holds, self.actions = [], [], []
            self.ended, self.completed, self.started_at = '', False, None
            why = self.driver.reset()
            if why:
                raise RuntimeError(f'rig_driver/reset refused: {why}')
        self._advance_until(lambda: self.driver.why_not_ready() == '', 5.0, 'the simulated rig did not come up')
        self._open()
        limit = self.now + (timeout if timeout is not None else self.program.duration(self.fs) + 10.0)
        while not self.ended and self.now < limit:
            self._step()
            if self.driver.faults and self._stalled('excitation'):   # nobody left to notice but the driver
                self._end('rig fault (the excitation stalled): ' + '; '.join(self.driver.fault_messages))
        if not self.ended:
            self.ended = f'timeout: the program had not ended after {limit - self.started_at:.1f} s'
        ended_at = self.now - self.started_at
        self._advance_until(self._at_rest, 10.0, '')
        return self._outcome(ended_at)

    def _open(self) -> None:
        try:
            self.grant = self.driver.open_stream(self.OWNER, self.lead)
        except StreamRefused as exc:
            raise RuntimeError(f'the driver refused the stream: {exc}') from exc
        self.session = ProgramSession.on_grant(self.program, self.fs, self.cfg.limits, self.grant, self.lead,
                                               self.batch, self.amplitude_control, detectors=self.detectors)
        self.runner = self.session.runner
        if self.record is not None:
            self.writer = RecordingWriter(self.record, {'source': 'rubber_rig.session.scenario', 'program':
                                                        self.program.name}, overwrite=True,
                                          clock_ns=lambda: int(round(self.now * 1e9)))
        self.started_at, self._measured_from = self.now, len(self.measured)
        self._wake_excitation()

    def _advance_until(self, done, seconds: float, why: str) -> None:
        end = self.now + seconds
        while not done() and self.now < end:
            self._step()
        if why and not done():
            raise RuntimeError(f'{why} within {seconds} s of scenario time ({self.driver.why_not_ready()})')

    def _step(self) -> None:
        """One poll period of scenario time: every component due wakes (controller first: it runs on its own CPU)."""
        self.rig.advance(serve=False)
        if self.actions and self.started_at is not None:
            due = [a for a in self.actions if self.now - self.started_at >= a[0]]
            self.actions = [a for a in self.actions if a not in due]
            for _, action in due:
                action(self)
        stalled = self._stalled_now()
        if 'controller' not in stalled:
            self.controller.serve(self.rig.now)
        if 'driver' not in stalled:
            self._wake_driver()
        if 'element_model' not in stalled and (self.model_inbox or self.cutter.waiting):
            self._wake_model()
        if self.session is not None and self.now >= self._excitation_due and 'excitation' not in stalled:
            self._wake_excitation()

    def _wake_driver(self) -> None:
        for batch in self.batches.arrived(self.now):
            self.gate.offer(self.OWNER, self.OWNER, *batch)
        why = self.owner_watch.lost(self.driver.stream, self.owner_timeout)
        if why:
            self.driver.owner_lost(why)
        block = self.driver.poll()
        while block is not None:     # rig_driver's poll: blocks into batches of BATCH_PERIOD (its batch_size 0)
            self._publish_samples(*self.batcher.add(block, self.samples_per_batch))
            # the node polls again until nothing comes: at the same instant that poll finds no new frame on the
            # bus, only the blocks this one received
            block = self.driver.io.next_block()
        self._publish_samples(self.batcher.due(MAX_BATCH_DELAY))

    def _publish_samples(self, *batches) -> None:
        for batch in batches:
            if batch is not None and self.writer is not None:
                self.writer.write_message(*sample_batch_record(batch))
            if batch is not None:
                self.measured.append(batch)
                self.samples.publish(batch, self.now, self._since_start())
                self.model_inbox.append(batch)

    def _wake_model(self) -> None:
        """The element model node: predict each sample batch, cut cycles once their block is known."""
        while self.model_inbox:
            m = self.model_inbox.popleft()
            if isinstance(m, tuple):       # a setpoint batch: (first, displacement, stream id, end, block)
                self.cutter.setpoints(m[0], len(m[1]), m[4], m[3])
                continue
            predicted, _ = self.predictor.process(m.first_sequence, m.sample_period, m.displacement, m.temperature)
            self.cutter.samples(m.first_sequence, m.sample_period, m.displacement, m.force, predicted, m.t0)
        self.cycles.extend(self.cutter.cycles())

    def _publish(self, first, x, block, end) -> None:
        """The excitation's setpoint batch, to the driver's command channel and the setpoints topic."""
        batch = (first, np.asarray(x, dtype=float), self.session.stream_id, bool(end), block)
        self.batches.publish(batch[:4], self.now, self._since_start())
        self.streamed.append(batch[:2])
        if self.writer is not None:
            self.writer.write_message(*setpoint_batch_record(self.now, batch, self.OWNER, 1.0 / self.fs))
        self.model_inbox.append(batch)

    def _act(self, events) -> None:
        """The strongest action among the detector events, as the excitation node takes it (program_watch)."""
        if not events or self.session is None:
            return
        self.events.extend((self.now - self.started_at, e) for e in events)
        s = self.session
        action = detector_action(events, s.held)
        if action is None:
            return
        if action.kind == 'end':
            self.driver.stop_stream(s.stream_id, self.program.rest_position, f'detector {action.detector}')
            s.runner.abort(action.reason)
            self._end(action.reason, completed=action.success)
            return
        why = s.why_not_hold() or self.driver.stop_stream(s.stream_id, s.runner.hold_target, action.reason, hold=True)
        if why:
            self._end(action.failed(why))
            return
        s.hold()
        self._end(f'held by {action.reason}: {action.message}')

    def _wake_excitation(self) -> None:
        """The excitation node's timer and callbacks: samples in, setpoints out, a heartbeat when one is due."""
        self._excitation_due = self.now + self.stream_period
        if self.now >= self._next_beat:
            self.peers.on_beat(Beat(self.OWNER, 1))
            self._next_beat = self.now + PERIOD
        s = self.session
        for b in self.samples.arrived(self.now):
            if not s.before_stream(b.first_sequence, len(b)):
                self._act(s.measured(b.first_sequence, b.displacement, b.setpoint, self.now,
                                     b.t0 + (len(b) - 1) * b.sample_period))
            if self.session is None:
                return
        while self.cycles:
            c = self.cycles.popleft().cycle
            m = c.measured
            self._act(s.judge_cycle(c.start_sequence, c.end_sequence, m['amplitude'], m['peak_amplitude'], m['mean'],
                                    cycle_properties(m), cycle_properties(c.model), c.residual_rms))
            if self.session is None:
                return
        self._operator(s)
        status = self.driver.status
        rig = RigView(status.state, status.state == 'fault' or bool(status.faults), list(status.fault_messages),
                      stream_id=self.driver.stream.stream_id if self.driver.stream is not None else 0,
                      last_event=status.extra.get('last_event', ''))
        if why := why_rig_stopped(rig, s.stream_id, s.end_sequence is not None):
            self._end(why)
            return
        if s.held:
            return
        s.stream(self._publish, self.now)
        if s.measured_to_end:
            self._end('', completed=not s.runner.aborted)

    def _operator(self, s: ProgramSession) -> None:
        """The hold and resume requests that are due, as the excitation node's on_hold handles them."""
        t = self.now - self.started_at
        for h in self.holds:
            if h[2] == 'due' and t >= h[0]:
                why = s.why_not_hold() or self.driver.stop_stream(s.stream_id, s.runner.hold_target,
                                                                  'operator hold', hold=True)
                h[2] = why or 'held'
                if not why:
                    s.hold()
                    self.log.append(f'held at {t:.3f} s')
            elif h[2] == 'held' and t >= h[1]:
                s.resume(self.driver.open_stream(self.OWNER, self.lead))
                h[2] = 'resumed'
                self.log.append(s.describe_resume())

    def _end(self, reason: str, completed: bool = False) -> None:
        self.ended, self.completed = reason or 'completed', completed
        self.session = None      # the excitation forgets the program (the runner keeps its block results)

    def _at_rest(self) -> bool:
        return self.driver.controller_state in ('idle', 'fault', 'holding') and self.driver.stream is None

    def _outcome(self, ended_at: float) -> Outcome:
        self._publish_samples(self.batcher.take())    # the rig is at rest: its last partial batch goes now
        if self.writer is not None:
            self.writer.close()
            self.writer = None
        blocks = self.measured[self._measured_from:]

        def cat(name):
            return np.concatenate([getattr(b, name) for b in blocks]) if blocks else np.zeros(0)
        seq = np.concatenate([b.sequence for b in blocks]) if blocks else np.zeros(0, dtype=np.int64)
        st = self.driver.status
        return Outcome(seq, cat('displacement'), cat('force'), cat('setpoint'), self.completed, self.ended,
                       ended_at, events=list(self.driver.events), faults=list(st.fault_messages),
                       counters=dict(self.driver.counters), blocks=self.runner.block_summaries,
                       detections=list(self.events), streamed=list(self.streamed),
                       played_end=self.driver.controller_sequence + 1)
