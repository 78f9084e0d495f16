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

"""The ROS side of ``rubber-rig bench``: the suite's nodes (started by cli.bench_nodes, as processes or in this
process) seen through a monitor node, the RunProgram goal with its feedback and cycle metrics, and the end of the
recording. ``bench.run`` drives it; the per-block table and the summary
files (``online.summary``) and the screen (``cli.bench_view``) know nothing of ROS.

Every wait here waits for something to happen, with a deadline; when the deadline passes the bench says what did
not happen (an error that stops it, or a warning where the summary can still count what is missing).
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from msg_defs.msg import RecorderStatus, RigStatus
from msg_defs.srv import RecorderControl
from rubber_rig.cli.bench_nodes import suite_facts
from rubber_rig.cli.bench_view import progress_text
from rubber_rig.cli.main import CommandError
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes.excitation_readiness import READY_STATES
from rubber_rig.nodes.foxglove_view_node import LAYOUT_FILE
from rubber_rig.nodes.monitor import SuiteMonitor
from rubber_rig.recording.loss import recording_loss
from rubber_rig.units import to_si

# the streams the recorder must record (matched with their publishers) before the first setpoint is sent
RECORDED_TOPICS = ('samples', 'prediction', 'setpoints', 'cycle_metrics', 'status', 'events', 'rig_configuration')
CONNECT_TIMEOUT = 30.0      # [s] nodes connected, goal accepted, recorder stopped
ABORT_TIMEOUT = 15.0        # [s] the program ends after Ctrl-C cancelled it
CATCH_UP_TIMEOUT = 5.0      # [s] the model predicts the last published samples
TAIL_TIMEOUT = 10.0         # [s] the rig at rest and its last samples recorded
RECORDER_LAG = 0.3          # [s] a recorder status this much newer than the run's last sample: it has that sample
REFRESH_PERIOD = 0.1        # [s] the screen refreshes ten times a second, at once when the program ends
MOVING = (RigStatus.STATE_RUNNING, RigStatus.STATE_RAMPING_DOWN)


@dataclass
class ProgramRun:
    """What the RunProgram goal did, as the bench saw it."""

    wall_time: float = 0.0
    interrupted: bool = False
    recording_error: str = ''
    result: Any = None                  # the action's result; None when it never came (interrupted)
    published: Any = None               # the samples' StreamStats when the rig came to rest
    future: Any = field(default=None, repr=False)


class BenchSession:
    """One bench run: the nodes started by ``nodes`` (bench_nodes: processes, or threads of ``launcher``'s process;
    the recorder first: nothing moves unless it records), watched and driven by a monitor node in ``launcher``.
    """

    def __init__(self, launcher, nodes, args, program_yaml: str, out_dir: Path, params_file):
        self.launcher, self.nodes = launcher, nodes
        self.monitor = launcher.spin(SuiteMonitor(context=launcher.context, namespace=args.namespace))
        mon = self.monitor
        nodes.start('recorder', {'output_dir': str(out_dir), 'metadata.test_program': program_yaml,
                                 'metadata.notes': f'rubber-rig bench --program {args.program}'})
        # before any other node exists: nothing can move unless the recorder records
        if not self.wait_for(lambda: mon.recorder_status is not None
                             and mon.recorder_status.state != RecorderStatus.STATE_IDLE, CONNECT_TIMEOUT):
            raise CommandError(f'cannot record, nothing started: {mon.recording_ready()}')
        if self.recorder_failed():
            raise CommandError(f'cannot record, nothing started: {mon.recorder_status.error}')
        nodes.start('element_model', {})
        exc_overrides = excitation_overrides(args)
        nodes.start('excitation', exc_overrides)
        drv_overrides = dict(driver_overrides(args), **nodes.driver_overrides(paced=not args.fast))
        self.cfg = suite_facts(params_file, drv_overrides, exc_overrides)
        ns = '/' + args.namespace.strip('/')
        self._hold_help = (f'the rig holds at rest; resume: rubber-rig hold --resume --namespace {ns} (signed with '
                           'the rig key), Ctrl-C ends the program, and it ends by itself after '
                           f'{self.cfg.hold_timeout:g} s (--hold-timeout)')
        nodes.start('rig_driver', drv_overrides)
        self.foxglove = ''
        if args.foxglove:
            nodes.start('foxglove_view', {'port': args.foxglove_port})
            self.foxglove = f'Foxglove: connect to ws://127.0.0.1:{args.foxglove_port}, import layout {LAYOUT_FILE}'
        self._n_feedback = self._n_cycles = self._n_events = 0
        self._silent: set[str] = set()     # nodes named silent on the terminal
        self._rest_since = None
        self._recorded_after = None        # [s] wall time the recorder must have reported after (the run's tail)

    def wait_for(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """``launcher.wait_for`` that also stops, naming it, when a node ends (or fails in its thread)."""
        def checked():
            self.nodes.check()
            return predicate()
        return self.launcher.wait_for(checked, timeout)

    def describe(self, program) -> list[str]:
        """The opening lines: program, rig and model, nodes (and where Foxglove connects)."""
        cfg, p = self.cfg, self.monitor.model_parameters
        model = f'{p.model_name} from {p.parameter_set or cfg.model_source}' if p is not None else 'element model'
        rig = (f'simulated rig in a process of its own on {cfg.backend}' if cfg.backend == 'udp_multicast'
               else f'rig: {cfg.backend}')
        lines = [f"rubber-rig bench: program '{program.name}' ({len(program.blocks)} blocks, "
                 f'{program.duration(cfg.sample_rate):.1f} s of excitation at {cfg.sample_rate:g} Hz, '
                 f"{'paced' if cfg.paced else 'as fast as possible'})",
                 f'{rig}, specimen {cfg.specimen}; model {model}',
                 'nodes: rig_driver, excitation, element_model, recorder' + (', foxglove_view' if self.foxglove else '')
                 + f' ({self.nodes.description})']
        return lines + ([self.foxglove] if self.foxglove else [])

    # -- before the program -----------------------------------------------------------------------------------------
    def recorder_failed(self) -> bool:
        st = self.monitor.recorder_status
        return st is not None and st.state == st.STATE_ERROR

    def rig_ready(self) -> str:
        """'' once rig_driver's status says the rig is ready for a program (not its first, pre-configure status)."""
        st = self.monitor.status
        if st is None:
            return f"no rig status on '{self.monitor.resolve_topic_name('status')}' yet"
        if st.state not in READY_STATES:
            why = '; '.join(st.fault_messages[-2:]) or st.last_event
            return f'rig is {st.state_name}' + (f': {why}' if why else '')
        return ''

    def wait_ready(self) -> str:
        """Wait until the excitation has seen the rig ready (not the driver's first, pre-configure status), the
        recorder records every stream and the bench's own live topics are matched; returns the recording's path.
        """
        mon = self.monitor
        ready = self.wait_for(lambda: self.recorder_failed() or (
            self.rig_ready() == '' and mon.action.server_is_ready() and mon.model_parameters is not None
            and mon.recording_ready(*RECORDED_TOPICS) == '' and not mon.unmatched()), CONNECT_TIMEOUT)
        if self.recorder_failed():
            raise CommandError(f'cannot record, nothing moved: {mon.recording_ready()}')
        if not ready:
            why = (self.rig_ready() or mon.recording_ready(*RECORDED_TOPICS)
                   or ('run_program missing' if not mon.action.server_is_ready() else '')
                   or ('no model_parameters' if mon.model_parameters is None else '')
                   or f"no publisher yet for {', '.join(mon.unmatched())}")
            raise CommandError(f'the nodes did not connect within {CONNECT_TIMEOUT:.0f} s ({why})')
        return mon.recorder_status.path

    def _result_of(self, future, timeout: float, what: str):
        if not self.wait_for(future.done, timeout):
            raise CommandError(f'timed out after {timeout:.0f} s waiting for {what}')
        return future.result()

    # -- the program --------------------------------------------------------------------------------------------------
    def new_cycle_metrics(self) -> list:
        """Cycle metrics that arrived since the last call."""
        cms = self.monitor.cycle_metrics[self._n_cycles:]
        self._n_cycles += len(cms)
        return cms

    def run_program(self, program_yaml: str, amplitude_control: bool, on_cycle: Callable, term) -> ProgramRun:
        """Send the goal and follow it to its end: progress line from the feedback, ``on_cycle`` for each cycle
        metrics message. A recorder error cancels the goal (the excitation also aborts on its own), so does Ctrl-C.
        """
        run = ProgramRun()
        t_start = time.monotonic()
        goal_handle = self._result_of(self.monitor.send_program(program_yaml, amplitude_control=amplitude_control),
                                      CONNECT_TIMEOUT, 'the goal to be accepted')
        if not goal_handle.accepted:
            raise CommandError('the excitation refused the program: another program is running on this ROS domain '
                               '(a second bench? give it its own --domain-id)')
        run.future = self.monitor.on_executor(goal_handle.get_result_async)   # (monitor.on_executor: why)
        try:
            while not run.future.done():
                self.nodes.check()
                if self.recorder_failed() and not run.recording_error:
                    run.recording_error = self.monitor.recorder_status.error
                    term.end_status()
                    term.line(f'RECORDING FAILED: {run.recording_error}; stopping the program (smooth ramp to rest)')
                    self.monitor.on_executor(goal_handle.cancel_goal_async)
                self._show_progress(term, t_start)
                self._show_events(term)
                self._show_silent(term)
                for c in self.new_cycle_metrics():
                    on_cycle(c)
                self.launcher.wait_for(run.future.done, REFRESH_PERIOD)
        except KeyboardInterrupt:
            run.interrupted = True
            term.end_status()
            term.line('interrupted: aborting the program (smooth ramp to rest) ...')
            self.monitor.on_executor(goal_handle.cancel_goal_async)
            if not self.launcher.wait_for(run.future.done, ABORT_TIMEOUT):
                term.line(f'warning: the program did not end within {ABORT_TIMEOUT:.0f} s of the abort '
                          '(no result from the excitation); the rig ramps to rest as the nodes shut down')
        term.end_status()
        run.wall_time = time.monotonic() - t_start
        return run

    def _show_events(self, term) -> None:
        """Each detector event once, as it arrives (between the table's rows)."""
        events = self.monitor.events[self._n_events:]
        self._n_events += len(events)
        for e in events:
            term.end_status()
            term.line(f'EVENT {e.action.upper()}: {e.message}')
            if e.action == 'hold':
                term.line(self._hold_help)

    def _show_silent(self, term) -> None:
        """A node of the suite that stops beating (stuck or gone) is named once, and again when it is back."""
        quiet = self.monitor.peers.silent()
        for name in sorted(set(quiet) - self._silent):
            term.end_status()
            term.line(f'NODE SILENT: {name} sent no heartbeat for {quiet[name]:.1f} s (stuck or gone)')
        for name in sorted(self._silent - set(quiet)):
            term.end_status()
            term.line(f'node back: {name} beats again')
        self._silent = set(quiet)

    def _show_progress(self, term, t_start: float) -> None:
        fb = self.monitor.feedback[self._n_feedback:]
        self._n_feedback += len(fb)
        if fb:
            term.status(progress_text(fb[-1], self.monitor.stats['samples'], t_start))

    def catch_up(self, run: ProgramRun, on_cycle: Callable, term) -> None:
        """Wait until the model has predicted every published sample (then the last cycle metrics are out), hand
        those to ``on_cycle`` and take the goal's result.
        """
        stats = self.monitor.stats

        def predicted_all():
            return stats['prediction'].next is not None and stats['samples'].next is not None \
                and stats['prediction'].next >= stats['samples'].next
        if not self.wait_for(predicted_all, CATCH_UP_TIMEOUT):
            term.line(f'warning: the model did not predict every published sample within {CATCH_UP_TIMEOUT:.0f} s '
                      '(the table may miss the last cycles)')
        for c in self.new_cycle_metrics():
            on_cycle(c)
        run.result = run.future.result().result if run.future.done() else None
        self._show_events(term)

    # -- the end of the recording -------------------------------------------------------------------------------------
    def _tail_recorded(self, run: ProgramRun) -> bool:
        """True once the rig has been at rest for two batch delays (a fault's ramp tail arrives after the goal
        ended) and the recorder has reported since (its status comes from the same executor that writes the
        samples, at least every 0.5 s); then ``run.published`` holds the samples published up to then.
        """
        mon, st = self.monitor.stats['samples'], self.monitor.status
        # unpaced (--fast), the simulated controller only ticks while setpoints are queued: after the program it
        # still says running, holding its last setpoint, but the driver has released the stream
        at_rest = st is not None and (st.state not in MOVING
                                      or (st.state == RigStatus.STATE_RUNNING and not st.stream_owner))
        if not at_rest:
            self._rest_since = self._recorded_after = None
            return False
        if self._rest_since is None:
            self._rest_since = time.monotonic()
        if time.monotonic() - self._rest_since < 2 * self.cfg.max_batch_delay:
            return False
        if self._recorded_after is None:
            run.published = copy.copy(mon)
            self._recorded_after = time.time() + RECORDER_LAG
        rs = self.monitor.recorder_status
        return self.recorder_failed() or (rs is not None and conv.to_seconds(rs.header.stamp) >= self._recorded_after)

    def stop_recording(self, run: ProgramRun, term) -> tuple[Path, dict]:
        """Stop the recorder once the run's tail is recorded; (MCAP file, its loss against what was published).

        A paced rig goes on sampling while it stands: the run's samples are those published up to the moment it
        came to rest (``run.published``), not those that keep arriving until the recorder stops.
        """
        if not self.wait_for(lambda: self._tail_recorded(run), TAIL_TIMEOUT):
            term.line('warning: the rig did not come to rest or the recorder did not receive the last samples '
                      f'within {TAIL_TIMEOUT:.0f} s; the summary counts what is missing')
        if self.recorder_failed() and not run.recording_error:
            run.recording_error = self.monitor.recorder_status.error
        stop = self._result_of(self.monitor.recorder(RecorderControl.Request.STOP), CONNECT_TIMEOUT,
                               'the recorder to stop')
        if not stop.file:
            raise CommandError(f'the recorder did not report its file: {stop.message or "no message"}')
        mcap = Path(stop.file)
        status = self.monitor.recorder_status
        rec_loss = recording_loss(mcap, run.published or self.monitor.stats['samples'],
                                  {'samples_lost_total': int(status.samples_lost) if status is not None else None})
        if run.recording_error:
            rec_loss['recorder_error'] = run.recording_error
        return mcap, rec_loss

    def summary(self, program, mcap: Path, run: ProgramRun, rec_loss: dict, rows: list[dict]) -> dict:
        """The run's summary (written as JSON and Markdown by ``online.summary.write_summary``)."""
        cfg, p, result = self.cfg, self.monitor.model_parameters, run.result
        blocks = [{'block_index': b.block_index, 'name': b.name, 'target_amplitude': b.target_amplitude,
                   'achieved_amplitude': b.achieved_amplitude, 'completed': b.completed, 'message': b.message}
                  for b in (result.blocks if result else [])]
        return {
            'program': program.name, 'recording': str(mcap), 'wall_time_s': run.wall_time,
            'interrupted': run.interrupted,
            'rig': {'backend': cfg.backend, 'sample_rate': cfg.sample_rate, 'paced': cfg.paced,
                    'specimen': cfg.specimen, 'batch_size': cfg.batch_size},
            'model': {'source': cfg.model_source, 'parameter_set': p.parameter_set if p else '',
                      'temperature': p.temperature if p else float('nan'),
                      'values': dict(zip(p.names, p.values, strict=True)) if p else {}},
            'result': {'success': bool(result.success) if result else False,
                       'message': result.message if result else 'no result (interrupted)', 'blocks': blocks},
            'loss': {'live': {k: v.as_dict() for k, v in self.monitor.stats.items()}, 'recording': rec_loss},
            # stamps are rig time (sample index / rate): only a paced rig keeps it in step with the wall clock
            'latency': self.monitor.latency_summary() if cfg.paced else {},
            'blocks': rows,
            'events': [conv.detector_event_dict(e) for e in (result.events if result else self.monitor.events)],
        }


def excitation_overrides(args) -> dict:
    """Excitation parameters the command line sets (the program comes by the action, not the parameter)."""
    overrides = {'program': ''}
    if getattr(args, 'hold_timeout', None):
        overrides['hold_timeout'] = to_si(args.hold_timeout, 'time')
    return overrides


def driver_overrides(args) -> dict:
    """rig_driver parameters the command line sets on top of the config file."""
    overrides = {'autostart': True}
    if args.rate:
        overrides['sample_rate'] = float(args.rate)
    if args.batch_size:
        overrides['batch_size'] = int(args.batch_size)
    if args.fast:
        overrides['paced'] = False
    if getattr(args, 'force_noise', None):
        overrides['sim.force_noise'] = to_si(args.force_noise, 'force')
    if getattr(args, 'damage', None):
        overrides['sim.damage'] = args.damage
    return overrides
