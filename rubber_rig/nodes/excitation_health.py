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

"""What the excitation node tells about a program besides its setpoints: the detector events it published, the
nodes that went silent (heartbeats) and whether the detectors were blind, in /diagnostics and in the goal's result.
"""
from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from msg_defs.action import RunProgram
from msg_defs.msg import DetectorEvent, Heartbeat
from rubber_rig.nodes import awaitables, topics
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes.auth import HEARTBEAT, annotate
from rubber_rig.nodes.heartbeat import PERIOD, SILENT
from rubber_rig.session.observed import BeatLog, ProgramWitness, StallWatch

STALL_SHOWN = 10.0   # [s] /diagnostics says this node stalled for this long after the stall


class ProgramHealth:
    """The events, silences and detector blindness of the running (or last) program of the excitation ``node``
    (which has ``state``, ``status``, ``session`` and ``recording``).
    """

    def __init__(self, node: Node):
        self.node = node
        self.events: list[DetectorEvent] = []   # detector events of the running (or last) program
        self.blind = ''                  # why the detectors were blind during the running program
        self.last_feedback_ns = 0        # node clock of the goal's latest feedback
        # the suite's other nodes, their silences measured from their own heartbeats (observed.BeatLog); a stall of
        # this node (self.stall) is not theirs
        self.me = node.get_fully_qualified_name()
        self.stall = StallWatch(SILENT)   # the node's own executor: a stall of its own is no silence of the others
        self.beats = BeatLog(SILENT, PERIOD)
        self.beat_topic = node.create_subscription(Heartbeat, topics.HEARTBEAT, self.on_beat,
                                                   topics.HEARTBEAT_QOS).topic_name
        self.witness = ProgramWitness(self.me, 0.0)
        self.silent_now: dict[str, float] = {}
        self.pub_diagnostics = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        node.create_timer(1.0, self.publish_diagnostics)
        node.create_timer(0.1, self.watch_peers)

    @property
    def silent_seen(self) -> dict[str, float]:
        """Node -> longest silence [s] seen during the running (or last) program."""
        return self.witness.silent_seen

    def on_beat(self, msg: Heartbeat) -> None:
        now = self.node.clock()
        self.stall.tick(now)
        # only signed beats (nodes/auth.py): a forged one must not hide a silent peer
        if msg.node != self.me and not self.node.auth.refuse(self.node, msg, HEARTBEAT, self.beat_topic):
            self.beats.beat(msg.node, msg.pid, msg.count, conv.to_seconds(msg.header.stamp), now)

    def start_program(self) -> None:
        self.blind, self.events = '', []
        # silences that began before the program (a node restarted just before it) are not the program's
        self.witness = ProgramWitness(self.me, self.node.clock(), silent_before=set(self.silent_now))

    def annotate(self, message: str, recording: str = '') -> str:
        """The goal's result message with what else happened: blind detectors, the recording (``recording``: its
        words, RecordingWatch.verdict), this node's own stalls and the peers that beat on through them, silences
        of the others measured from their own heartbeats.
        """
        if self.blind:
            message += f' (detectors were blind: {self.blind})'
        if recording:
            message += f' ({recording})'
        elif self.node.recording.lost:
            message += f' ({self.node.recording.lost})'
        for words in self.witness.words(self.beats, self.stall, self.node.clock()):
            message += f' ({words})'
        return message

    def publish_diagnostics(self) -> None:
        """/diagnostics: the program state and its detector events, named after the node."""
        node = self.node
        running = node.session is not None
        last = self.events[-1] if self.events else None
        level = DiagnosticStatus.OK
        if last is not None and last.action != 'record':
            level = DiagnosticStatus.WARN
        blind = self.detectors_blind()
        lost = node.recording.lost if running else ''
        if lost:
            level = DiagnosticStatus.WARN
        silent = ', '.join(f'{n} ({a:.1f} s)' for n, a in self.silent_now.items())   # as watch_peers saw it
        if silent:
            level = DiagnosticStatus.WARN
        if blind:
            level = DiagnosticStatus.WARN
            if not self.blind:
                node.get_logger().warning(f'detectors blind: {blind}')
            self.blind = blind
        # a stall of this node's own executor in the last STALL_SHOWN seconds: said, so that an operator does not
        # look for the cause in the nodes it did not hear meanwhile
        stalls = self.stall.stalls
        stalled = (f'this node stalled for {stalls[-1][1] - stalls[-1][0]:.1f} s (its callbacks did not run)'
                   if stalls and self.node.clock() - stalls[-1][1] < STALL_SHOWN else '')
        if stalled:
            level = DiagnosticStatus.WARN
        values = {'state': node.state, 'program': node.session.runner.program.name if running else '',
                  'detector_events': len(self.events), 'last_event': last.message if last else '',
                  'detectors_blind': blind, 'recording_lost': lost, 'nodes_silent': silent, 'stalled': stalled}
        values['goals_rejected_busy'] = node.admission.rejected      # run_program goals rejected while one ran
        values['last_goal_rejection'] = node.admission.last_rejection
        reasons = [stalled, f'nodes silent: {silent}' if silent else '', f'detectors blind: {blind}' if blind else '',
                   lost, last.message if last is not None and last.action != 'record' else '']
        msg = DiagnosticArray()
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.status.append(annotate(DiagnosticStatus(   # + what it refused unsigned or forged (samples, goals, beats)
            level=level, name=node.get_fully_qualified_name(), hardware_id='rubber_rig',
            message=next((x for x in reasons if x), f'program {node.state}'),
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()]), node.auth))
        self.pub_diagnostics.publish(msg)

    def watch_peers(self) -> None:
        """Name a node that went silent (no heartbeat for heartbeat.SILENT, 0.75 s) once per silence in the log;
        while a program runs, remember it for the goal's result. The rig driver's silence ends the program
        elsewhere (status_timeout).
        """
        now = self.node.clock()
        if stall := self.stall.tick(now):
            self.node.get_logger().error(
                f'{self.me} (this node) stalled for {stall[1] - stall[0]:.1f} s: its callbacks did not run; what it '
                'did not hear then is no silence of the others')
        if self.node.session is not None:
            quiet = self.witness.watch(self.beats, self.stall, now)
        else:
            quiet = self.beats.quiet(now, self.stall)
        log = self.node.get_logger()
        for name, age in quiet.items():
            if name not in self.silent_now:
                log.error(f'{name} is silent: no heartbeat for {age:.1f} s (stuck or gone)')
        for name in set(self.silent_now) - set(quiet):
            log.info(f'{name} beats again')
        changed = set(quiet) != set(self.silent_now)
        self.silent_now = quiet
        if changed:
            self.publish_diagnostics()    # at once, not at the next 1 s tick

    def publish_events(self, events, program, publisher) -> None:
        """Publish the detector events of ``program`` on ``publisher``, keep them, and log them."""
        t = self.node.get_clock().now().nanoseconds * 1e-9
        for e in events:
            msg = conv.detector_event_msg(e, program.name, program.blocks[e.block].name, t)
            self.events.append(msg)
            publisher.publish(msg)
            # one call site per severity: rclpy refuses a call site whose severity changes between calls (an
            # event recorded and then one that holds, from one line, raised and lost the hold)
            if e.action == 'record':
                self.node.get_logger().info(e.message)
            else:
                self.node.get_logger().warning(e.message)

    def detectors_blind(self) -> str:
        """Why the running program's cycle detectors cannot trip ('' when they judge cycles as they come)."""
        session, status = self.node.session, self.node.status
        if session is None or status is None:
            return ''
        since = session.detectors_blind(status.sample_rate)
        why = [f'no cycle_metrics from element_model for {since:.1f} s of a periodic block (is it running?)'
               if since else '', session.monitor.blind if session.monitor is not None else '']
        return '; '.join(w for w in why if w)

    def publish_feedback(self, goal_handle, p, now_ns: int) -> None:
        """The goal's feedback for the runner's Progress ``p``, at most every feedback_period (node clock)."""
        if now_ns - self.last_feedback_ns >= self.node.feedback_period * 1e9:
            self.last_feedback_ns = now_ns
            goal_handle.publish_feedback(self.feedback(p))

    def feedback(self, p) -> RunProgram.Feedback:
        """The goal's feedback: the runner's Progress ``p`` and the detector events so far."""
        return RunProgram.Feedback(block_index=p.block_index, block_count=p.block_count, block_name=p.block_name,
                                   cycle=p.cycle, cycles_total=p.cycles_total, target_amplitude=p.target_amplitude,
                                   achieved_amplitude=p.achieved_amplitude, progress=p.fraction,
                                   events=len(self.events),
                                   last_event=self.events[-1] if self.events else DetectorEvent())

    async def result_when_recorded(self, session, success: bool, ended: bool, outcome, done) -> None:
        """The result of the program of ``session`` that just ended, once the recording's words are known
        (RecordingWatch.verdict waits at most RESULT_WAIT for the recorder): kept in node.result, logged, and set on
        the goal's future ``done`` (None for a program started without a goal).
        """
        node = self.node
        end_wall, end_sample = self.node.clock(), session.measured_sequence
        words = node.recording.verdict(outcome, end_sample, end_wall, self.beats)
        while words is None:
            await awaitables.sleep(node, 0.02)
            words = node.recording.verdict(outcome, end_sample, end_wall, self.beats)
        node.result = result = self.result(session.runner, success, ended, words)
        node.get_logger().info(f'program ended: {result.message}')
        if done is not None and not done.done():
            done.set_result(result)

    def result(self, runner, success: bool, ended: bool, recording: str = '') -> RunProgram.Result:
        """The goal's result for the program of ``runner``: a success only if asked for and it was not aborted
        (or it ``ended`` by an end-of-test trigger), with the block summaries, the events and what else happened
        (the recording's words ``recording`` among them).
        """
        return RunProgram.Result(success=success and (ended or not runner.aborted),
                                 message=self.annotate(runner.abort_reason if runner.aborted else 'completed',
                                                       recording),
                                 blocks=[conv.block_summary_msg(s) for s in runner.block_summaries],
                                 events=list(self.events))
