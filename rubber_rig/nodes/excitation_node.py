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

"""excitation: runs test programs on the rig, streaming setpoints ahead of the rig.

Action:      run_program (msg_defs/action/RunProgram; feedback: block, cycle, achieved amplitude; result:
             per-block summaries and why it ended). A goal that arrives while one runs is rejected at once
             (session.admission: the reason and the count in the log and the diagnostics); every other goal
             either runs or ends at once with the reason it cannot (rig not ready, invalid program, no recording).
Services:    ~/abort (std_srvs/Trigger: ramp to rest now), ~/hold (msg_defs/HoldProgram: true = hold, false = resume,
             signed), ~/load_program (msg_defs/srv/LoadProgram: validate without running)
Subscribes:  samples (msg_defs/RigSampleBatch: amplitude control, progress), status (msg_defs/RigStatus, latched:
             sample rate, limits, faults, who owns the stream), recorder_status (msg_defs/RecorderStatus, with
             require_recording), cycle_metrics (msg_defs/CycleMetrics from element_model: what the detectors judge)
Publishes:   setpoints (msg_defs/SetpointBatch), program (std_msgs/String, latched: YAML of the running program),
             events (msg_defs/DetectorEvent: every detector trip), /diagnostics (program state, detector events)
Calls:       <rig_driver>/open_stream, <rig_driver>/stop_stream
Signatures:  its setpoints, stream requests and heartbeats carry the rig key's signature; it takes only signed
             goals and sample batches (nodes/auth.py; refusals counted and named in /diagnostics)

A program starts only on a stream the driver grants (one owner at a time), from wherever the rig holds (an approach
ramp leads to the program's start). Setpoints are generated from the sample index by a rubber_rig.session.
ProgramSession (never from wall-clock time) and published ``lead_time`` ahead of the sample the rig plays. Abort,
cancel and hold go to the driver directly (its controller ramps at once, instead of after the queued lead); a rig
that stops the stream, faults or goes silent ends the goal with the reason. When a program may start and when it
must stop is decided by the ROS-free session.program_watch, session.recorder_watch and session.peer_watch on the
node's clock; this node converts messages, feeds them and acts. No callback lets an exception take the node down.
Detectors (rubber_rig.excitation.detectors, README "Detectors") judge every steady cycle the element model measures;
a trip's action (record, warn, hold, end) takes the operator's own hold and abort paths. A held program resumes
(``~/hold`` false) with the full cycles its block had not yet run.
"""
from __future__ import annotations

import math
import traceback

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import String
from std_srvs.srv import Trigger

from msg_defs.action import RunProgram
from msg_defs.msg import CycleMetrics, DetectorEvent, RecorderStatus, RigSampleBatch, RigStatus, SetpointBatch
from msg_defs.srv import HoldProgram, LoadProgram, OpenStream, StopStream
from rubber_rig.excitation import Program, read_program, with_defaults
from rubber_rig.nodes import awaitables, topics
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes import excitation_readiness as readiness
from rubber_rig.nodes import excitation_services as services
from rubber_rig.nodes.auth import (
    OPEN_STREAM,
    RUN_PROGRAM,
    SAMPLES,
    SETPOINT_STREAM,
    SETPOINTS,
    STOP_STREAM,
    declare_auth,
)
from rubber_rig.nodes.draining import create_draining_subscription
from rubber_rig.nodes.excitation_health import ProgramHealth
from rubber_rig.nodes.excitation_params import declare_excitation_parameters
from rubber_rig.nodes.excitation_recording import recorder_name, recorder_topic, recorder_view, samples_topic
from rubber_rig.nodes.heartbeat import PERIOD, start_heartbeat
from rubber_rig.nodes.spin import spin_node, with_process_nice
from rubber_rig.nodes.ticks import NodeTicks
from rubber_rig.session import GoalAdmission, ProgramSession, RigTime
from rubber_rig.session.program_watch import ProgramWatch, detector_action, why_rig_stopped
from rubber_rig.session.recorder_watch import RecorderWatch


class ExcitationNode(Node):
    events_executor_refuses = 'tasks that await futures (a program ran it at 31 % of a core, 5 wake-ups/s)'

    def __init__(self, node_name: str = 'excitation', clock=None, **kwargs):
        super().__init__(node_name, **kwargs)
        # [s] the clock of the node's rules: its ROS clock (simulated with use_sim_time, as its timers) or a test's
        self.clock = clock or (lambda: self.get_clock().now().nanoseconds * 1e-9)
        self.params = declare_excitation_parameters(self)   # lead_time, batch_size, timeouts, ... (checked)
        self.pending_program = self.params.program   # (Program, YAML) of the program parameter, run once ready
        self.auth = declare_auth(self)        # signs its commands, verifies samples and goals (nodes/auth.py)
        self.status = None              # the latest rig status (msg_defs/RigStatus)
        self.health = ProgramHealth(self)   # events, silent peers, blind detectors: diagnostics and the result
        p = self.params     # the start and stop rules (session.program_watch, session.recorder_watch) on self.clock
        self.watch = ProgramWatch(p.status_timeout, p.hold_timeout, p.start_timeout, self.health.stall, p.rig_driver)
        self.recording = RecorderWatch(p.require_recording, p.recorder_timeout, samples_topic(self),
                                       recorder_topic(self), self.health.stall)
        self.recorder_node = ''         # who publishes the recorder status (its heartbeat confirms a recording)
        self.rig_time = RigTime()       # the rig clock of a sequence, from the latest sample batch's stamp
        self.session: ProgramSession | None = None         # the running program on its stream
        self.opening = False            # an open_stream request is under way
        self.goal_handle = None
        self._done: Future | None = None
        self.result: RunProgram.Result | None = None   # result of the last run (also for program runs)

        # commands to the driver's private channel, the same batches to `setpoints` for observers (topics.py)
        self.pub_stream = self.create_publisher(
            SetpointBatch, topics.setpoint_stream_topic(self.params.rig_driver, self.get_fully_qualified_name()),
            topics.STREAM_QOS)
        self.pub_setpoints = self.create_publisher(SetpointBatch, topics.SETPOINTS, topics.STREAM_QOS)
        self.pub_program = self.create_publisher(String, topics.PROGRAM, topics.LATCHED_QOS)
        self.pub_events = self.create_publisher(DetectorEvent, topics.EVENTS, topics.EVENT_QOS)
        self.create_subscription(CycleMetrics, topics.CYCLE_METRICS, self.on_cycle_metrics, topics.EVENT_QOS)
        self.sub_samples = create_draining_subscription(   # read on the stream tick, not a wake-up per batch
            self, RigSampleBatch, topics.SAMPLES, self.on_samples, topics.STREAM_QOS, polled=True)
        self.create_subscription(RigStatus, topics.STATUS, self.on_status, topics.LATCHED_QOS)
        self.create_subscription(RecorderStatus, topics.RECORDER_STATUS, self.on_recorder_status, topics.LATCHED_QOS)
        self.open_client = self.create_client(OpenStream, f'{self.params.rig_driver}/open_stream')
        self.stop_client = self.create_client(StopStream, f'{self.params.rig_driver}/stop_stream')
        self.create_service(Trigger, '~/abort', lambda req, res: services.on_abort(self, req, res))
        self.create_service(HoldProgram, '~/hold', lambda req, res: services.on_hold(self, req, res))
        self.create_service(LoadProgram, '~/load_program', lambda req, res: readiness.load_program(self, req, res))
        self.admission = GoalAdmission()   # one goal at a time; the others rejected at once, counted
        self.action = ActionServer(self, RunProgram, 'run_program', execute_callback=self.execute,
                                   goal_callback=self.admit_goal,
                                   cancel_callback=lambda _: CancelResponse.ACCEPT, **topics.ACTION_SERVICES_QOS)
        self.ticks = NodeTicks(self, {   # one timer (nodes/ticks.py): streaming first, then the health's duties
            'samples': (self.params.stream_period, self.sub_samples.drain),   # what the rig measured, then
            'stream': (self.params.stream_period, self.stream), **self.health.duties(),
            'heartbeat': (PERIOD, start_heartbeat(self, lambda: self.state, timer=False))})

    @property
    def state(self) -> str:
        """idle, held, or the running program's state (running, aborting, ...)."""
        s = self.session
        return 'idle' if s is None else 'held' if s.held else s.runner.state

    # -- inputs -----------------------------------------------------------------------------------------------
    def on_status(self, msg: RigStatus) -> None:
        rig, self.status = readiness.rig_view(msg), msg
        self.watch.on_rig_status(rig, self.clock())
        s = self.session
        if s is None or not s.stream_id or self.opening:
            return
        if why := why_rig_stopped(rig, s.stream_id, s.end_sequence is not None):
            self._end(why)

    def on_recorder_status(self, msg: RecorderStatus) -> None:
        self.recorder_node = recorder_name(self) or self.recorder_node
        s = self.session     # (the sample it expects next, and whether it measured one, while a program runs)
        why, lost = self.recording.on_status(recorder_view(msg), self.clock(), s and s.measured_sequence,
                                             s is not None and s.next_sample is not None)
        if lost:
            self.get_logger().error(lost)
        if why:
            self.abort_program(why)

    def on_samples(self, msg: RigSampleBatch) -> None:
        if self.auth.refuse(self, msg, SAMPLES, self.sub_samples.topic_name):
            return     # a forged batch neither proves the driver alive nor ends a program (detectors never see it)
        self.watch.on_samples(self.clock())   # the driver is alive as much as its status says
        s = self.session
        if s is not None and s.before_stream(msg.first_sequence, len(msg.displacement)):
            return                       # from before this program's stream
        self.rig_time.observe(msg.first_sequence, conv.to_seconds(msg.header.stamp))
        if s is None:
            return
        try:
            self.act(s.measured(msg.first_sequence, conv.as_array(msg.displacement), conv.as_array(msg.setpoint),
                                self.clock(), conv.last_sample_time(msg)))   # (arrival and stamp: the rig's pace)
        except Exception as exc:   # noqa: BLE001 - a bad batch must not take the node down
            self.abort_program(f'internal error on a sample batch: {exc!r}')

    def on_cycle_metrics(self, msg: CycleMetrics) -> None:
        if self.session is None:
            return
        try:
            self.act(self.session.judge_cycle(
                msg.start_sequence, msg.end_sequence, msg.amplitude, msg.peak_amplitude, msg.mean,
                conv.cycle_properties_dict(msg.measured), conv.cycle_properties_dict(msg.model), msg.residual_rms))
        except Exception as exc:   # noqa: BLE001 - a bad message must not take the node down
            self.get_logger().error(f'detectors failed on a cycle: {exc!r}\n{traceback.format_exc()}')

    def act(self, events) -> None:
        """Publish detector events and take the strongest action among them."""
        if not events or self.session is None:
            return
        self.health.publish_events(events, self.session.runner.program, self.pub_events)
        action = detector_action(events, self.session.held)   # end, hold, or None: published, nothing else
        if action is not None and action.kind == 'end':
            self.abort_program(action.reason, success=action.success)
        elif action is not None and (why := self.hold_program(action.reason)):
            self.abort_program(action.failed(why))

    # -- starting programs ------------------------------------------------------------------------------------------
    def rig_ready(self) -> str:
        """'' when a program can start, else why not (session.program_watch, with the graph's facts)."""
        now = self.clock()
        return self.watch.why_not_start(now, self.get_fully_qualified_name(), self.session is not None or self.opening,
                                        readiness.links(self), readiness.recording_ready(self, now))

    async def _open_stream(self):
        """Ask the driver for the stream (new program or resume); the grant, or None if it did not answer."""
        self.opening = True
        try:
            return await awaitables.call(self, self.open_client, self.auth.sign(OpenStream.Request(
                owner=self.get_fully_qualified_name(), lead_time=self.params.lead_time), OPEN_STREAM), 2.0)
        finally:
            self.opening = False

    async def open_and_start(self, program: Program, text: str, amplitude_control: bool) -> str:
        """Check the program against the rig, ask the driver for the stream and start the program on it. '' on
        success, else why not.
        """
        try:
            readiness.check_fits(self, program)
        except ValueError as exc:      # ProgramError, LimitError: name block and field
            return str(exc)
        grant = await self._open_stream()
        if grant is None:
            return f'{self.params.rig_driver}/open_stream did not answer within 2 s'
        if not grant.success:
            return f'the rig refused the stream: {grant.message}'
        fs = self.status.sample_rate
        try:
            # check_fits() checked the program against these limits (and the force model) before the stream was
            # asked for; from the grant on, every moment before the first batch counts against the driver
            self.session = ProgramSession.on_grant(
                program, fs, conv.limits_from_msg(self.status.limits), grant, math.ceil(self.params.lead_time * fs),
                self.params.batch_size, amplitude_control, self.params.compensation_memory,
                detectors=with_defaults(program.all_detectors(), self.params.default_detectors))
        except ValueError as exc:
            return str(exc)
        self.result = None
        self.recording.start_program(self.clock())
        self.health.start_program()
        self.pub_program.publish(String(data=text))
        self.get_logger().info(self.session.describe())
        self.stream()                    # the first lead now, not a timer period later
        return ''

    async def _start_pending(self, program, text):
        why = await self.open_and_start(program, text, self.params.amplitude_control)
        if why:
            self.get_logger().error(f"program '{program.name}' not started: {why}")

    # -- streaming (timer) ------------------------------------------------------------------------------------------
    def stream(self) -> None:
        self.health.stall.tick(self.clock())
        if (goal := self.goal_handle) is not None and goal.is_cancel_requested and self.session is not None:
            self.abort_program('goal cancelled')   # looked at every stream period: no timer of its own
        try:
            self._stream()
        except Exception as exc:   # noqa: BLE001 - no callback may take the node down
            self.get_logger().error(f'streaming failed: {exc!r}\n{traceback.format_exc()}')
            self.abort_program(f'internal error while streaming: {exc!r}')

    def _stream(self) -> None:
        s = self.session
        if s is None:
            if self.pending_program is not None and not self.rig_ready():
                program, text = self.pending_program
                self.pending_program = None
                self.executor.create_task(self._start_pending(program, text))
            return
        now = self.clock()
        if not s.held and s.stream_id and (lost := self.recording.check(now, s.measured_sequence)):
            self.get_logger().error(lost)   # said once; with require_recording why_stop ends the program
        if why := self.watch.why_stop(now, s.held, bool(s.stream_id), self.recording.why_stop(now)):
            self.abort_program(why)
            return
        if s.held or not s.stream_id:
            return
        s.stream(self._publish, now)     # lead ahead of the sample the rig plays now (session.rig_pace)
        if self.goal_handle is not None:
            self.health.publish_feedback(self.goal_handle, s.runner.progress)
        if s.measured_to_end:
            self._finish(success=not s.runner.aborted)   # measured to the end: the summaries are complete

    def _publish(self, first, x, block, end=False):
        dt, now = 1.0 / self.status.sample_rate, self.get_clock().now().nanoseconds * 1e-9
        msg = conv.setpoint_batch_msg(first, dt, x, block, t=self.rig_time.of(first, dt, now),
                                      stream_id=self.session.stream_id, source=self.get_fully_qualified_name(),
                                      end_of_stream=end)
        self.pub_stream.publish(self.auth.sign(msg, SETPOINT_STREAM))
        self.pub_setpoints.publish(self.auth.sign(msg, SETPOINTS))   # signed again: a copy cannot command the rig

    # -- ending programs --------------------------------------------------------------------------------------------
    def abort_program(self, reason: str, success: bool = False) -> bool:
        """Stop the running program now: the driver's controller ramps to its rest position at once (not after the
        queued lead); the goal ends with `reason` (a success only for an end-of-test trigger). False if none runs.
        """
        if self.session is None:
            return False
        self._stop_stream(StopStream.Request.ACTION_ABORT, reason, self.session.runner.program.rest_position)
        self._end(reason, success)
        return True

    def _end(self, reason: str, success: bool = False) -> None:
        if (s := self.session) is not None:
            s.runner.abort(reason)     # the line says what this node knew (session.view): whose lag ended it
        self.get_logger().warning(f'program stopped: {reason}' + (f' ({s.view(self.clock())})' if s else ''))
        self._finish(success=success, ended=True)

    def _finish(self, success: bool, ended: bool = False) -> None:
        """The stream is free now; the result waits for word from the recorder (at most RESULT_WAIT)."""
        if (s := self.session) is not None:
            self.session, outcome = None, self.recording.end_program()
            self.executor.create_task(self.health.result_when_recorded(s, success, ended, outcome, self._done))

    def _stop_stream(self, action: int, reason: str, target: float = 0.0) -> None:
        if self.session is None or not self.session.stream_id:
            return
        if not self.stop_client.service_is_ready():
            # the stream still ends (no more setpoints): the driver faults it after stream_timeout and ramps
            self.get_logger().error(f'{self.params.rig_driver}/stop_stream is not available: the rig ramps to rest '
                                    f'on the driver\'s stream_timeout instead of at once ({reason})')
            return
        self.stop_client.call_async(self.auth.sign(StopStream.Request(
            stream_id=self.session.stream_id, action=action, target=float(target), reason=reason), STOP_STREAM))

    # -- action -------------------------------------------------------------------------------------------------------
    def admit_goal(self, goal) -> GoalResponse:
        if self.auth.refuse(self, goal, RUN_PROGRAM, f'{self.get_fully_qualified_name()}/run_program'):
            return GoalResponse.REJECT     # unsigned or forged: a stranger cannot run a program (counted, named)
        why = self.admission.reject(self.session.runner.program.name if self.session is not None else '')
        if why:
            self.get_logger().warning(f'goal rejected, {why} ({self.admission.rejected} rejected so far)',
                                      throttle_duration_sec=1.0)
            return GoalResponse.REJECT
        self.admission.reserve()          # at once: a goal arriving before this one executes is busy too
        return GoalResponse.ACCEPT

    async def execute(self, goal_handle) -> RunProgram.Result:
        self.admission.start(goal_handle.goal_id.uuid)
        try:
            return await self._execute(goal_handle)
        finally:
            self.admission.finish()

    async def _execute(self, goal_handle) -> RunProgram.Result:
        goal = goal_handle.request
        try:
            program, text = read_program(goal.program_path, goal.program_yaml)
            await readiness.wait_for_statuses(self)
            why = self.rig_ready()
            if not why:
                why = await self.open_and_start(program, text, goal.amplitude_control)
        except (ValueError, OSError) as exc:   # ProgramError, LimitError: name block and field
            why = str(exc)
        except Exception as exc:   # noqa: BLE001 - a goal must end with a reason, never take the node down
            why = f'internal error: {exc!r}'
        if why:
            self.get_logger().warning(f'goal refused: {why}')
            goal_handle.abort()
            return RunProgram.Result(success=False, message=why)
        self.goal_handle, self._done = goal_handle, (done := Future())
        try:
            result = await done
        finally:
            if self._done is done:     # a next goal may have started while this result waited for the recorder
                self.goal_handle, self._done = None, None
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif result.success:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    def hold_program(self, reason: str) -> str:
        """Hold the running program at its block mean (the driver keeps the stream for us). '' or why not."""
        s = self.session
        if why := s.why_not_hold():
            return why
        self._stop_stream(StopStream.Request.ACTION_HOLD, reason, s.runner.hold_target)
        s.hold()
        self.watch.on_hold(self.clock())
        self.get_logger().warning(f'program held at {s.runner.hold_target * 1e3:.4f} mm: {reason}')
        return ''

    async def _resume(self):
        s = self.session
        grant = await self._open_stream()
        if self.session is not s or s is None:
            return
        if grant is None or not grant.success:
            self._end('resume refused: ' + (grant.message if grant is not None else 'rig_driver did not answer'))
            return
        s.resume(grant)
        self.get_logger().info(s.describe_resume())


def main(args=None):
    spin_node(with_process_nice(ExcitationNode), args)   # a process of its own: its niceness from parameter nice


if __name__ == '__main__':
    main()
