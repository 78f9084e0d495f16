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

"""excitation: runs test programs on the rig, streaming setpoints ahead of the measured samples.

Action:      run_program (msg_defs/action/RunProgram; feedback: block, cycle, achieved amplitude; result:
             per-block summaries and why it ended). Every goal is accepted and then either runs or ends at once
             with the reason it cannot (busy, rig not ready, invalid program, no recording).
Services:    ~/abort (std_srvs/Trigger: ramp to rest now), ~/hold (std_srvs/SetBool: true = hold, false = resume),
             ~/load_program (msg_defs/srv/LoadProgram: validate without running)
Subscribes:  samples (msg_defs/RigSampleBatch: amplitude control, progress), status (msg_defs/RigStatus,
             latched: sample rate, limits, faults, who owns the stream), recorder_status (msg_defs/RecorderStatus,
             with require_recording)
Subscribes:  cycle_metrics (msg_defs/CycleMetrics from element_model: what the detectors judge)
Publishes:   setpoints (msg_defs/SetpointBatch), program (std_msgs/String, latched: YAML of the running program),
             events (msg_defs/DetectorEvent: every detector trip), /diagnostics (program state, detector events)
Calls:       <rig_driver>/open_stream, <rig_driver>/stop_stream

A program starts only on a stream the driver grants (one owner at a time), from wherever the rig holds (an
approach ramp leads to the program's start). Setpoints are generated from the sample index by
rubber_rig.excitation.ProgramRunner (never from wall-clock time) and published ``lead_time`` ahead of the
latest measured sample. Abort, cancel and hold go to the driver directly (its controller ramps at once,
instead of after the queued lead); a rig that stops the stream, faults or goes silent ends the goal with the
reason. No callback lets an exception take the node down: it ends the running program and logs.

Detectors (rubber_rig.excitation.detectors): the program's own, plus the ``default_detectors`` of the types it
does not declare, judge every steady cycle the element model measures and the end-of-test triggers on every
sample batch. A trip is a DetectorEvent on ``events``, in the goal's feedback and result and in the
diagnostics; its action (record, warn, hold, end) goes through the same hold and abort paths an operator uses.
A held program resumes (``~/hold`` false) with the full cycles its block had not yet run.
"""
from __future__ import annotations

import math
import time
import traceback

import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger

from msg_defs.action import RunProgram
from msg_defs.msg import CycleMetrics, DetectorEvent, RecorderStatus, RigSampleBatch, RigStatus, SetpointBatch
from msg_defs.srv import LoadProgram, OpenStream, StopStream
from rubber_rig.excitation import Program, ProgramRunner, read_program
from rubber_rig.excitation.detectors import (
    DEFAULTS,
    DetectorError,
    Monitor,
    blind_for,
    cycle_of,
    parse_detectors,
    strongest,
    with_defaults,
)
from rubber_rig.excitation.limits import check_program, element_force_model
from rubber_rig.excitation.streamer import SetpointStreamer
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes import topics
from rubber_rig.nodes.heartbeat import Peers, start_heartbeat
from rubber_rig.nodes.params import ParameterError, declare
from rubber_rig.nodes.spin import spin_node

READY_STATES = (RigStatus.STATE_IDLE, RigStatus.STATE_RUNNING, RigStatus.STATE_HOLDING)


class ExcitationNode(Node):

    def __init__(self, node_name: str = 'excitation', **kwargs):
        super().__init__(node_name, **kwargs)
        self.program_param = declare(self, 'program', '', 'program (shipped name or YAML path) to run as soon as '
                                     'the rig is ready; empty: wait for a run_program goal')
        self.amplitude_control = declare(self, 'amplitude_control', True, 'adjust command amplitude and mean '
                                         'so the measured amplitude reaches the target (program parameter only)')
        self.compensation_memory = declare(self, 'compensation_memory', True, 'with amplitude control, each '
                                           'block starts from the gain and mean offset earlier blocks of the run '
                                           'learned (false: every block starts uncompensated)')
        self.lead_time = declare(self, 'lead_time', 0.5, 'how far ahead of the latest measured sample '
                                 'setpoints are streamed', range=(0.02, 5.0), units='s')
        self.batch_size = declare(self, 'batch_size', 50, 'setpoints per SetpointBatch', range=(1, 5000))
        self.stream_period = declare(self, 'stream_period', 0.02, 'period of the streaming timer',
                                     range=(0.001, 0.5), units='s')
        self.feedback_period = declare(self, 'feedback_period', 0.2, 'period of action feedback',
                                       range=(0.01, 10.0), units='s')
        self.rig_driver = declare(self, 'rig_driver', 'rig_driver', 'name of the rig_driver node whose '
                                  'open_stream/stop_stream services this node calls (relative: same namespace)')
        self.status_timeout = declare(self, 'status_timeout', 0.8, 'neither a rig_driver status nor a sample batch '
                                      'for this long ends a running program (the driver is gone)',
                                      range=(0.2, 10.0), units='s')
        self.start_timeout = declare(self, 'start_timeout', 5.0, 'a goal waits up to this long for fresh rig and '
                                     'recorder statuses and for DDS to match our topics (after a launch or a '
                                     'node restart discovery can take seconds) before it is refused',
                                     range=(0.0, 60.0), units='s')
        self.require_recording = declare(self, 'require_recording', False, 'start a program only while the '
                                         "recorder reports recording this namespace's samples, and stop it if "
                                         'the recording fails')
        self.recorder_timeout = declare(self, 'recorder_timeout', 2.0, 'with require_recording: a recorder status '
                                        'older than this stops a running program (the recorder publishes it every '
                                        '0.5 s)', range=(0.5, 60.0), units='s')
        self.force_model_set = declare(self, 'force_model', 'swing_arm_joint_20C', 'element-model parameter set that '
                                       'predicts each block\'s peak force before start (refused above '
                                       "limits.force_max); '' = no force prediction")
        self.hold_timeout = declare(self, 'hold_timeout', 600.0, 'a program held (operator or detector) this long '
                                    'without a resume ends: the rig ramps to the rest position and the goal says why',
                                    range=(1.0, 86400.0), units='s')
        default_detectors = declare(self, 'default_detectors', 'default', "detectors every program runs with "
                                    "besides its own (a program's detector of the same name replaces one): "
                                    "'default' (residual, stiffness_change, force_drift, tracking; README "
                                    "'Detectors'), '' for none, or a YAML list like [{type: residual, threshold: 5}]")
        try:
            raw = list(DEFAULTS) if default_detectors == 'default' else yaml.safe_load(default_detectors) or []
            self.default_detectors = parse_detectors(raw, 'default_detectors')
        except (DetectorError, yaml.YAMLError) as exc:
            raise ParameterError(self, 'default_detectors', str(exc)) from None
        if self.stream_period >= self.lead_time / 2:
            raise ParameterError(self, 'stream_period', f'{self.stream_period} s must be below half '
                                 f'of lead_time ({self.lead_time} s) or the driver could starve')
        try:
            self.force_model = element_force_model(self.force_model_set) if self.force_model_set else None
        except (ValueError, OSError) as exc:
            raise ParameterError(self, 'force_model', str(exc)) from None
        self._pending = None
        if self.program_param:  # validate at start: a wrong name fails here, naming the parameter
            try:
                self._pending = read_program(self.program_param)
            except (ValueError, OSError) as exc:
                raise ParameterError(self, 'program', str(exc)) from None

        self.status: RigStatus | None = None
        self._status_wall = 0.0
        self._driver_wall = 0.0          # the latest status or sample batch: the driver is alive
        # endpoint gids of the publishers of a topic and when they last changed (a node restarted)
        self._publisher_sets: dict[str, tuple[frozenset, float]] = {}
        self.recorder: RecorderStatus | None = None
        self._recorder_wall = 0.0
        self.next_sample = None          # sequence after the latest measured sample
        self._time_base: tuple[int, float] | None = None   # (sequence, rig time [s]) of the latest sample batch
        self.runner: ProgramRunner | None = None
        self.streamer: SetpointStreamer | None = None   # keeps the runner lead_time ahead of the measurement
        self.stream_id = 0               # the stream the driver granted us (0: none)
        self.start_sequence = 0
        self.end_sequence = None         # sequence after the last setpoint of the finished runner
        self.held = False                # stream held by the driver (hold); resume opens it again
        self._opening = False            # an open_stream request is under way
        self.goal_handle = None
        self._done: Future | None = None
        self._last_feedback = 0.0
        self.result: RunProgram.Result | None = None   # result of the last run (also for program runs)
        self.monitor: Monitor | None = None   # the running program's detectors
        self._last_cycle_end, self._blind = 0, ''   # end of the latest judged cycle; why detectors were blind
        self._recorded_by, self._recording_lost = '', ''   # the recording a program started in; why it was lost
        self.events: list[DetectorEvent] = []  # detector events of the running (or last) program
        self._held_at = None             # sequence after the last sample measured before a hold
        self._held_wall = 0.0            # time.monotonic() of the hold (hold_timeout)
        self._elapsed_samples = 0        # program samples measured (rig time of the program, holds excluded)

        # commands to the driver's private channel, the same batches to `setpoints` for observers (topics.py)
        self.pub_stream = self.create_publisher(
            SetpointBatch, topics.setpoint_stream_topic(self.rig_driver, self.get_fully_qualified_name()),
            topics.STREAM_QOS)
        self.pub_setpoints = self.create_publisher(SetpointBatch, topics.SETPOINTS, topics.STREAM_QOS)
        self.pub_program = self.create_publisher(String, topics.PROGRAM, topics.LATCHED_QOS)
        self.pub_events = self.create_publisher(DetectorEvent, topics.EVENTS, topics.EVENT_QOS)
        self.pub_diagnostics = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.create_subscription(CycleMetrics, topics.CYCLE_METRICS, self.on_cycle_metrics, topics.EVENT_QOS)
        self.sub_samples = self.create_subscription(RigSampleBatch, topics.SAMPLES, self.on_samples,
                                                    topics.STREAM_QOS)
        self.create_subscription(RigStatus, topics.STATUS, self.on_status, topics.LATCHED_QOS)
        self.create_subscription(RecorderStatus, topics.RECORDER_STATUS, self.on_recorder_status,
                                 topics.LATCHED_QOS)
        self.open_client = self.create_client(OpenStream, f'{self.rig_driver}/open_stream')
        self.stop_client = self.create_client(StopStream, f'{self.rig_driver}/stop_stream')
        self.create_service(Trigger, '~/abort', self.on_abort)
        self.create_service(SetBool, '~/hold', self.on_hold)
        self.create_service(LoadProgram, '~/load_program', self.on_load_program)
        self.action = ActionServer(self, RunProgram, 'run_program', execute_callback=self.execute,
                                   goal_callback=lambda _: GoalResponse.ACCEPT,
                                   cancel_callback=lambda _: CancelResponse.ACCEPT)
        self.create_timer(self.stream_period, self.stream)
        self.create_timer(1.0, self.publish_diagnostics)
        start_heartbeat(self, lambda: 'idle' if self.runner is None else 'held' if self.held else self.runner.state)
        self.peers = Peers(self)           # the suite's other nodes: silent ones are named in diagnostics
        self._silent_seen = {}             # node -> longest silence seen during the running program [s]
        self._silent_now: dict[str, float] = {}
        self._silent_before: set[str] = set()
        self.create_timer(0.1, self.watch_peers)

    @property
    def samples_topic(self) -> str:
        ns = self.get_namespace().rstrip('/')
        return f'{ns}/{topics.SAMPLES}'

    def _publishers_changed(self, topic: str) -> tuple[int, float]:
        """(number of publishers of ``topic``, time.monotonic() when that set of publishers last changed)."""
        gids = frozenset(bytes(i.endpoint_gid) for i in self.get_publishers_info_by_topic(topic))
        known, since = self._publisher_sets.get(topic, (None, 0.0))
        if gids != known:
            since = time.monotonic()
            self._publisher_sets[topic] = (gids, since)
        return len(gids), since

    # -- inputs -----------------------------------------------------------------------------------------------
    def on_status(self, msg: RigStatus) -> None:
        self.status, self._status_wall = msg, time.monotonic()
        self._driver_wall = self._status_wall
        if self.runner is None or not self.stream_id or self._opening:
            return
        if msg.state == RigStatus.STATE_FAULT or msg.faults:   # (ramping_down while the fault's ramp runs)
            self._end('rig fault: ' + '; '.join(msg.fault_messages or conv.fault_names(msg.faults)))
        elif msg.stream_id != self.stream_id and self.end_sequence is None:
            # the driver took the stream away (rig_driver/abort, deactivate, a limit change): say what it did
            self._end(f'the rig stopped the program: {msg.last_event or msg.state_name}')

    def on_recorder_status(self, msg: RecorderStatus) -> None:
        self.recorder, self._recorder_wall = msg, time.monotonic()
        if self.require_recording and self.runner is not None and msg.state == RecorderStatus.STATE_ERROR:
            self.abort_program(f'recording failed: {msg.error or "recorder error"}')
        elif self.runner is not None:
            self.check_recording()

    def recording_path(self) -> str:
        """The file the recorder reports recording this namespace's samples into ('' if none, or stale)."""
        r = self.recorder
        if r is None or time.monotonic() - self._recorder_wall > self.recorder_timeout \
                or r.state != RecorderStatus.STATE_RECORDING or self.samples_topic not in r.topics:
            return ''
        return r.path or '(unnamed file)'

    def check_recording(self) -> None:
        """A program that started while being recorded and whose recording stopped says so, once: in the log,
        the diagnostics and the goal's result (without require_recording the program runs on; with it, the
        program is stopped elsewhere).
        """
        if not self._recorded_by or self._recording_lost:
            return
        now = self.recording_path()
        if now == self._recorded_by:
            return
        r, age = self.recorder, time.monotonic() - self._recorder_wall
        why = (f'no recorder status for {age:.1f} s (the recorder is gone)' if age > self.recorder_timeout
               else f'the recorder is {r.state_name}' + (f': {r.error}' if r.error else '') if not now
               else f'the recorder switched to {now}')
        self._recording_lost = (f'recording lost from about sample {self.next_sample}: {why}; the samples after '
                                f'it are not in {self._recorded_by}')
        self.get_logger().error(self._recording_lost)

    def on_samples(self, msg: RigSampleBatch) -> None:
        # samples prove the driver alive as well as its status does: one late status message (DDS can hold a
        # topic back for a second when a subscriber process dies) must not stop a running program
        self._driver_wall = time.monotonic()
        n = len(msg.displacement)
        if self.runner is not None and msg.first_sequence + n <= self.start_sequence:
            return                       # from before this program's stream
        self.next_sample = msg.first_sequence + n
        self._time_base = (msg.first_sequence, conv.to_seconds(msg.header.stamp))
        if self.runner is not None and n and not self.held:
            try:
                self.runner.feed_measurement(msg.first_sequence, conv.as_array(msg.displacement))
                self._elapsed_samples += n
                block, block_cycles, program_cycles = self.runner.cycles_done(self.next_sample - 1)
                if block >= 0:
                    self.act(self.monitor.on_progress(block, block_cycles, program_cycles, self.elapsed,
                                                      self.next_sample))
            except Exception as exc:   # noqa: BLE001 - a bad batch must not take the node down
                self.abort_program(f'internal error on a sample batch: {exc!r}')

    @property
    def elapsed(self) -> float:
        """Rig time the running program has been measured for [s] (holds excluded)."""
        return self._elapsed_samples / self.status.sample_rate if self.status else 0.0

    def on_cycle_metrics(self, msg: CycleMetrics) -> None:
        r = self.runner
        if r is None or self.held or self.monitor is None:
            return
        try:
            cycle = cycle_of(r, msg.start_sequence, msg.end_sequence, msg.amplitude, msg.peak_amplitude, msg.mean,
                             conv.cycle_properties_dict(msg.measured), conv.cycle_properties_dict(msg.model),
                             msg.residual_rms, self.elapsed)
            if cycle is None:            # not a cycle of this program's blocks (an approach ramp, another stream)
                return
            self._last_cycle_end = max(self._last_cycle_end, msg.end_sequence)
            self.act(self.monitor.on_cycle(cycle))
        except Exception as exc:   # noqa: BLE001 - a bad message must not take the node down
            self.get_logger().error(f'detectors failed on a cycle: {exc!r}\n{traceback.format_exc()}')

    def act(self, events) -> None:
        """Publish detector events and take the strongest action among them."""
        if not events or self.runner is None:
            return
        r = self.runner
        t = self.get_clock().now().nanoseconds * 1e-9
        for e in events:
            msg = conv.detector_event_msg(e, r.program.name, r.program.blocks[e.block].name, t)
            self.events.append(msg)
            self.pub_events.publish(msg)
            # one call site per severity: rclpy refuses a call site whose severity changes between calls (an
            # event recorded and then one that holds, from one line, raised and lost the hold)
            if e.action == 'record':
                self.get_logger().info(e.message)
            else:
                self.get_logger().warning(e.message)
        top = strongest(events)
        if top.action == 'end':
            trigger = top.kind in ('cycle_count', 'elapsed_time')
            self.abort_program(f'ended by detector: {top.message}', success=trigger)
        elif top.action == 'hold' and not self.held:
            why = self.hold_program(f'detector {top.detector}')
            if why:
                self.abort_program(f'detector {top.detector} asked for a hold, which failed ({why}): {top.message}')

    # -- starting programs ------------------------------------------------------------------------------------------
    def rig_ready(self) -> str:
        """'' when a program can start, else why not."""
        if self.status is None:
            return "no rig status received on 'status' yet (is rig_driver active?)"
        if time.monotonic() - self._status_wall > self.status_timeout * 3:
            return f'the rig status is {time.monotonic() - self._status_wall:.1f} s old (is rig_driver running?)'
        if self.status.state not in READY_STATES:
            why = '; '.join(self.status.fault_messages[-2:])
            return f'rig is {self.status.state_name}' + (f': {why} (rig_driver/reset to acknowledge)' if why else '')
        if self.status.stream_owner and self.status.stream_owner != self.get_fully_qualified_name():
            return f'the rig is streaming for {self.status.stream_owner}'
        if self.runner is not None or self._opening:
            return 'a program is already running'
        return self.links_ready() or self.recording_ready()

    def links_ready(self) -> str:
        """'' once our setpoints publisher and samples subscription are matched with every endpoint the graph
        shows on those topics (the driver's among them). Right after a launch or a driver restart the status can
        arrive before they are: a stream opened then would run dry (no samples pace it) or send to nobody.
        """
        for what, matched, known in (
                ('samples subscription', self.sub_samples.get_publisher_count(),
                 self.count_publishers(self.samples_topic)),
                ('setpoint stream publisher', self.pub_stream.get_subscription_count(),
                 self.count_subscribers(self.pub_stream.topic_name)),
                ('setpoints publisher', self.pub_setpoints.get_subscription_count(),
                 self.count_subscribers(self.pub_setpoints.topic_name))):
            if matched < max(known, 1):
                return f'waiting for discovery: our {what} is matched with {matched} of {max(known, 1)} endpoints'
        return ''

    def _statuses_fresh(self, since: float) -> bool:
        """The rig status, the recorder status (with require_recording) and our topics are ready to judge a goal
        that arrived at ``since`` (time.monotonic()). A recorder error counts only if reported since then: the
        error of a recorder that was just replaced must not refuse a goal the new one would record.
        """
        now = time.monotonic()
        rig = self.status is not None and now - self._status_wall <= self.status_timeout
        rec = not self.require_recording or (
            self.recorder is not None and now - self._recorder_wall <= self.recorder_timeout
            and ((self.recorder.state == RecorderStatus.STATE_ERROR and self._recorder_wall >= since)
                 or self.recording_ready() == ''))
        return rig and rec and not self.links_ready()

    def recording_ready(self) -> str:
        if not self.require_recording:
            return ''
        r = self.recorder
        if r is None:
            return "require_recording: no recorder status on 'recorder_status' (is the recorder running?)"
        if time.monotonic() - self._recorder_wall > self.recorder_timeout:
            return f'require_recording: no recorder status for {time.monotonic() - self._recorder_wall:.1f} s'
        # a restarted recorder is a new publisher of its status: the last status of the one it replaced
        # (latched, fresh for recorder_timeout) must not stand for it
        ns = self.get_namespace().rstrip('/')
        _, since = self._publishers_changed(f'{ns}/{topics.RECORDER_STATUS}')
        if self._recorder_wall <= since:
            return 'require_recording: waiting for a status of the recorder that runs now (it was restarted)'
        if r.state != RecorderStatus.STATE_RECORDING:
            return f'require_recording: the recorder is {r.state_name}' + (f': {r.error}' if r.error else '')
        if self.samples_topic not in r.topics:
            return f'require_recording: the recorder does not record {self.samples_topic} yet'
        # a restarted rig_driver is a new publisher: until the recorder has matched it, its first samples
        # would be published to nobody and not even counted lost (the recorder never sees them). A recorder
        # status from before the publishers changed counts the old ones: wait for a newer one
        known, since = self._publishers_changed(self.samples_topic)
        if self._recorder_wall <= since:
            return (f'require_recording: waiting for a recorder status newer than the last change of '
                    f'{self.samples_topic} publishers')
        matched = (r.topic_publishers[r.topics.index(self.samples_topic)]
                   if len(r.topic_publishers) == len(r.topics) else known)
        if matched < known:
            return (f'require_recording: the recorder is matched with {matched} of the {known} publishers of '
                    f'{self.samples_topic} (it has not discovered the restarted rig_driver yet)')
        return ''

    def prepare(self, program: Program, amplitude_control: bool) -> None:
        """Check the program against the rig's limits (and the force model) before anything is asked of the
        driver; ValueError names the block and field.
        """
        limits = conv.limits_from_msg(self.status.limits)
        limits.force_model = self.force_model
        check_program(limits, program, self.status.sample_rate)

    async def _open_stream(self):
        """Ask the driver for the stream (new program or resume); the grant, or None if it did not answer."""
        self._opening = True
        try:
            return await self._call(self.open_client, OpenStream.Request(
                owner=self.get_fully_qualified_name(), lead_time=self.lead_time), 2.0)
        finally:
            self._opening = False

    async def open_and_start(self, program: Program, text: str, amplitude_control: bool) -> str:
        """Ask the driver for the stream and start the runner on it. '' on success, else why not."""
        grant = await self._open_stream()
        if grant is None:
            return f'{self.rig_driver}/open_stream did not answer within 2 s'
        if not grant.success:
            return f'the rig refused the stream: {grant.message}'
        limits = conv.limits_from_msg(self.status.limits)
        try:
            # prepare() checked the program against these limits (and the force model) before the stream was
            # asked for; from the grant on, every moment before the first batch counts against the driver
            self.runner = ProgramRunner(program, self.status.sample_rate, limits, amplitude_control,
                                        start_sequence=grant.first_sequence,
                                        compensation_memory=self.compensation_memory,
                                        start_position=grant.position, start_velocity=grant.velocity,
                                        check_program=False)
        except ValueError as exc:
            self._stop_stream(StopStream.Request.ACTION_ABORT, f'program refused: {exc}')
            return str(exc)
        fs = self.status.sample_rate
        self.streamer = SetpointStreamer(self.runner, math.ceil(self.lead_time * fs), self.batch_size)
        self.stream_id, self.held = grant.stream_id, False
        self.start_sequence = grant.first_sequence
        self.next_sample = None          # samples of an earlier rig (a restarted driver counts from 0) do not count
        self.end_sequence = None
        self.result = None
        self.monitor = Monitor(with_defaults(program.all_detectors(), self.default_detectors))
        self._last_cycle_end, self._blind = grant.first_sequence, ''
        self.events, self._elapsed_samples = [], 0
        self._recorded_by = self.recording_path()     # the recording this program starts in ('' if none)
        # silences that began before the program (a node restarted just before it) are not the program's
        self._silent_seen, self._silent_before = {}, set(self._silent_now)
        self._recording_lost = ''
        self.pub_program.publish(String(data=text))
        self.get_logger().info(f"program '{program.name}': {len(program.blocks)} blocks, "
                               f'{program.duration(self.status.sample_rate):.1f} s, stream {grant.stream_id} from '
                               f'sample {grant.first_sequence}, rig at {grant.position * 1e3:.4f} mm')
        self.stream()                    # the first lead now, not a timer period later
        return ''

    # -- streaming (timer) ------------------------------------------------------------------------------------------
    def stream(self) -> None:
        try:
            self._stream()
        except Exception as exc:   # noqa: BLE001 - no callback may take the node down
            self.get_logger().error(f'streaming failed: {exc!r}\n{traceback.format_exc()}')
            self.abort_program(f'internal error while streaming: {exc!r}')

    def _stream(self) -> None:
        if self.runner is None:
            if self._pending is not None and not self.rig_ready():
                program, text = self._pending
                self._pending = None
                self.executor.create_task(self._start_pending(program, text))
            return
        if self.held and time.monotonic() - self._held_wall > self.hold_timeout:
            self.abort_program(f'held for {self.hold_timeout:g} s without a resume (hold_timeout): ramp to rest')
            return
        if self.held or not self.stream_id:
            return
        self.check_recording()
        if self.require_recording and time.monotonic() - self._recorder_wall > self.recorder_timeout:
            self.abort_program(f'recording lost: no recorder status for {time.monotonic() - self._recorder_wall:.1f}'
                               ' s (the recorder is gone)')
            return
        if time.monotonic() - self._driver_wall > self.status_timeout:
            self.abort_program(f'{self.rig_driver} silent for {time.monotonic() - self._driver_wall:.1f} s '
                               '(no status, no samples): the rig controller ramps to rest on its own host '
                               'watchdog')
            return
        r = self.runner
        measured = self.start_sequence if self.next_sample is None else max(self.next_sample, self.start_sequence)
        sent = False
        for chunk in self.streamer.due(measured):
            self._publish(chunk.first_sequence, chunk.displacement, chunk.block, end=chunk.end)
            sent = True
        if r.finished and self.end_sequence is None:
            self.end_sequence = r.sequence
            if not sent:
                self._publish(r.sequence, [], -1, end=True)
        elif not sent and not r.finished:
            # keep-alive (no setpoints): the driver's stream_timeout watches for us
            self._publish(r.sequence, [], r.block_index if r.state == 'running' else -1)
        now = self.get_clock().now().nanoseconds * 1e-9
        if self.goal_handle is not None and now - self._last_feedback >= self.feedback_period:
            self._last_feedback = now
            self.goal_handle.publish_feedback(self.feedback())
        if self.end_sequence is not None and self.next_sample is not None and self.next_sample >= self.end_sequence:
            self._finish(success=not r.aborted)   # measured to the end: the summaries are complete

    def _publish(self, first, x, block, end=False):
        dt = 1.0 / self.status.sample_rate
        msg = conv.setpoint_batch_msg(first, dt, x, block, t=self.rig_time(first, dt), stream_id=self.stream_id,
                                      source=self.get_fully_qualified_name(), end_of_stream=end)
        self.pub_stream.publish(msg)
        self.pub_setpoints.publish(msg)

    def rig_time(self, sequence: int, dt: float) -> float:
        """When the rig will apply sample `sequence` [s, the rig's clock]: the stamp of the latest measured
        batch plus the samples between (a setpoint batch is stamped with the time it is for, as a sample batch
        is with the time it was measured). Before any sample arrived, the first setpoint is taken to apply now
        (this node's clock): a new stream starts with its first batch.
        """
        if self._time_base is None:
            self._time_base = (sequence, self.get_clock().now().nanoseconds * 1e-9)
        first, t0 = self._time_base
        return t0 + (sequence - first) * dt

    def feedback(self) -> RunProgram.Feedback:
        p = self.runner.progress
        return RunProgram.Feedback(block_index=p.block_index, block_count=p.block_count, block_name=p.block_name,
                                   cycle=p.cycle, cycles_total=p.cycles_total, target_amplitude=p.target_amplitude,
                                   achieved_amplitude=p.achieved_amplitude, progress=p.fraction,
                                   events=len(self.events),
                                   last_event=self.events[-1] if self.events else DetectorEvent())

    # -- ending programs --------------------------------------------------------------------------------------------
    def abort_program(self, reason: str, success: bool = False) -> bool:
        """Stop the running program now: the driver's controller ramps to the program's rest position at once
        (not after the queued lead); the goal ends with `reason` (a success only for an end-of-test trigger).
        False if nothing runs.
        """
        if self.runner is None:
            return False
        self._stop_stream(StopStream.Request.ACTION_ABORT, reason, self.runner.program.rest_position)
        self._end(reason, success)
        return True

    def _end(self, reason: str, success: bool = False) -> None:
        if self.runner is not None:
            self.runner.abort(reason)
        self.get_logger().warning(f'program stopped: {reason}')
        self._finish(success=success, ended=True)

    def _finish(self, success: bool, ended: bool = False) -> None:
        r = self.runner
        if r is None:
            return
        result = RunProgram.Result(success=success and (ended or not r.aborted),
                                   message=r.abort_reason if r.aborted else 'completed',
                                   blocks=[conv.block_summary_msg(s) for s in r.block_summaries],
                                   events=list(self.events))
        if self._blind:
            result.message += f' (detectors were blind: {self._blind})'
        if self._recording_lost:
            result.message += f' ({self._recording_lost})'
        if self._silent_seen:
            result.message += ' (silent during the program: ' + ', '.join(
                f'{n} up to {a:.1f} s' for n, a in sorted(self._silent_seen.items())) + ')'
        self.result = result
        self.runner, self.stream_id, self.held = None, 0, False
        self.get_logger().info(f'program ended: {result.message}')
        if self._done is not None and not self._done.done():
            self._done.set_result(result)

    def _stop_stream(self, action: int, reason: str, target: float = 0.0) -> None:
        if not self.stream_id:
            return
        if not self.stop_client.service_is_ready():
            # the stream still ends (no more setpoints): the driver faults it after stream_timeout and ramps
            self.get_logger().error(f'{self.rig_driver}/stop_stream is not available: the rig ramps to rest on '
                                    f'the driver\'s stream_timeout instead of at once ({reason})')
            return
        self.stop_client.call_async(StopStream.Request(stream_id=self.stream_id, action=action,
                                                       target=float(target), reason=reason))

    async def _call(self, client, request, timeout: float):
        """Await a service response, or None after `timeout` seconds (or if the service is not there)."""
        deadline = time.monotonic() + timeout
        while not client.service_is_ready():
            if time.monotonic() >= deadline:
                return None
            await self._sleep(0.05)
        done = Future()
        future = client.call_async(request)
        future.add_done_callback(lambda f: done.done() or done.set_result(f.result()))
        timer = self.create_timer(timeout, lambda: done.done() or done.set_result(None))
        try:
            return await done
        finally:
            self.destroy_timer(timer)

    async def _sleep(self, seconds: float):
        done = Future()
        timer = self.create_timer(seconds, lambda: done.done() or done.set_result(True))
        try:
            await done
        finally:
            self.destroy_timer(timer)

    async def _start_pending(self, program, text):
        try:
            self.prepare(program, self.amplitude_control)
            why = await self.open_and_start(program, text, self.amplitude_control)
        except ValueError as exc:
            why = str(exc)
        if why:
            self.get_logger().error(f"program '{program.name}' not started: {why}")

    # -- action -------------------------------------------------------------------------------------------------------
    async def execute(self, goal_handle) -> RunProgram.Result:
        goal = goal_handle.request
        try:
            program, text = read_program(goal.program_path, goal.program_yaml)
            # a goal sent right after launch (or a restart of the driver or recorder) may arrive before their
            # latched statuses: wait for them, bounded
            since = time.monotonic()
            deadline = since + self.start_timeout
            while not self._statuses_fresh(since) and time.monotonic() < deadline:
                await self._sleep(0.05)
            why = self.rig_ready()
            if not why:
                self.prepare(program, goal.amplitude_control)
                why = await self.open_and_start(program, text, goal.amplitude_control)
        except (ValueError, OSError) as exc:   # ProgramError, LimitError: name block and field
            why = str(exc)
        except Exception as exc:   # noqa: BLE001 - a goal must end with a reason, never take the node down
            why = f'internal error: {exc!r}'
        if why:
            self.get_logger().warning(f'goal refused: {why}')
            goal_handle.abort()
            return RunProgram.Result(success=False, message=why)
        self.goal_handle, self._done = goal_handle, Future()

        def check_cancel():
            if goal_handle.is_cancel_requested and self.runner is not None:
                self.abort_program('goal cancelled')
        cancel_timer = self.create_timer(0.01, check_cancel)
        try:
            result = await self._done
        finally:
            self.destroy_timer(cancel_timer)
            self.goal_handle, self._done = None, None
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif result.success:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    # -- services ---------------------------------------------------------------------------------------------
    def on_abort(self, request, response):
        if self.abort_program('operator abort (excitation/abort)'):
            response.success, response.message = True, 'the rig ramps to the rest position'
        else:
            response.success, response.message = False, 'no program running'
        return response

    def on_hold(self, request, response):
        r = self.runner
        if r is None:
            response.success, response.message = False, 'no program running'
        elif request.data:
            why = self.hold_program('operator hold (excitation/hold)')
            response.success = not why
            response.message = why or f'holding at {r.hold_target * 1e3:.4f} mm (the block mean)'
        else:
            if not self.held:
                response.success, response.message = False, 'not holding'
                return response
            self.executor.create_task(self._resume())
            response.success, response.message = True, 'resuming the held block with the cycles it has not run'
        return response

    def hold_program(self, reason: str) -> str:
        """Hold the running program at its block mean (the driver keeps the stream for us). '' or why not."""
        r = self.runner
        if self.held or r.state != 'running':
            return f'cannot hold: the program is {"held" if self.held else r.state}'
        self._stop_stream(StopStream.Request.ACTION_HOLD, reason, r.hold_target)
        r.hold()
        self.held, self._held_at, self._held_wall = True, self.next_sample, time.monotonic()
        self.get_logger().warning(f'program held at {r.hold_target * 1e3:.4f} mm: {reason}')
        return ''

    async def _resume(self):
        r = self.runner
        grant = await self._open_stream()
        if self.runner is not r or r is None:
            return
        if grant is None or not grant.success:
            self._end('resume refused: ' + (grant.message if grant is not None else 'rig_driver did not answer'))
            return
        fs = self.status.sample_rate
        self.streamer = SetpointStreamer(self.runner, math.ceil(self.lead_time * fs), self.batch_size)
        self.stream_id, self.held = grant.stream_id, False
        self.start_sequence = grant.first_sequence
        self.next_sample = None          # samples of an earlier rig (a restarted driver counts from 0) do not count
        r.resume_at(grant.first_sequence, grant.position, measured_sequence=self._held_at)
        self._last_cycle_end = grant.first_sequence     # the hold is not blindness
        self.monitor.rearm()

    def publish_diagnostics(self) -> None:
        """/diagnostics: the program state and its detector events, named after this node."""
        r = self.runner
        state = 'idle' if r is None else ('held' if self.held else r.state)
        last = self.events[-1] if self.events else None
        level = DiagnosticStatus.OK
        if last is not None and last.action != 'record':
            level = DiagnosticStatus.WARN
        blind = self.detectors_blind()
        if self._recording_lost and r is not None:
            level = DiagnosticStatus.WARN
        silent = ', '.join(f'{n} ({a:.1f} s)' for n, a in self._silent_now.items())   # as watch_peers saw it
        if silent:
            level = DiagnosticStatus.WARN
        if blind:
            level = DiagnosticStatus.WARN
            if not self._blind:
                self.get_logger().warning(f'detectors blind: {blind}')
            self._blind = blind
        values = {'state': state, 'program': r.program.name if r else '', 'detector_events': len(self.events),
                  'last_event': last.message if last else '', 'detectors_blind': blind,
                  'recording_lost': self._recording_lost if r is not None else '', 'nodes_silent': silent}
        reasons = [f'nodes silent: {silent}' if silent else '', f'detectors blind: {blind}' if blind else '',
                   self._recording_lost if r is not None else '',
                   last.message if last is not None and last.action != 'record' else '']
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status.append(DiagnosticStatus(
            level=level, name=self.get_fully_qualified_name(), hardware_id='rubber_rig',
            message=next((x for x in reasons if x), f'program {state}'),
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()]))
        self.pub_diagnostics.publish(msg)

    def watch_peers(self) -> None:
        """Name a node that went silent (no heartbeat for heartbeat.SILENT, 0.75 s) once per silence in the log;
        while a program runs, remember it for the goal's result. The rig driver's silence ends the program
        elsewhere (status_timeout).
        """
        quiet = self.peers.silent()
        for name, age in quiet.items():
            if name not in self._silent_now:
                self.get_logger().error(f'{name} is silent: no heartbeat for {age:.1f} s (stuck or gone)')
            if self.runner is not None and name not in self._silent_before:
                self._silent_seen[name] = max(age, self._silent_seen.get(name, 0.0))
        for name in set(self._silent_now) - set(quiet):
            self.get_logger().info(f'{name} beats again')
            self._silent_before.discard(name)
        changed = set(quiet) != set(self._silent_now)
        self._silent_now = quiet
        if changed:
            self.publish_diagnostics()    # at once, not at the next 1 s tick

    def detectors_blind(self) -> str:
        """Why the running program's cycle detectors cannot trip ('' when they judge cycles as they come)."""
        r = self.runner
        if r is None or self.held or self.monitor is None or not self.monitor.needs_cycles \
                or self.next_sample is None or self.status is None:
            return ''
        since = blind_for(r, self.next_sample - 1, self._last_cycle_end, self.status.sample_rate)
        return (f'no cycle_metrics from element_model for {since:.1f} s of a periodic block (is it running?)'
                if since else '')

    def on_load_program(self, request, response):
        try:
            program, _ = read_program(request.path, request.program_yaml)
            rate = self.status.sample_rate if self.status else 1000.0
            if self.status is not None:
                limits = conv.limits_from_msg(self.status.limits)
                limits.force_model = self.force_model
                check_program(limits, program, rate)
            response.success, response.message = True, f"program '{program.name}' is valid"
            response.block_count, response.duration = len(program.blocks), program.duration(rate)
        except (ValueError, OSError) as exc:
            response.success, response.message = False, str(exc)
        except Exception as exc:   # noqa: BLE001 - a bad request must never take the node down
            response.success, response.message = False, f'internal error: {exc!r}'
        return response


def main(args=None):
    spin_node(ExcitationNode, args)


if __name__ == '__main__':
    main()
