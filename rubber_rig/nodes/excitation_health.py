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
The rules (who is silent, whether this node stalled, the level and words) are rubber_rig.session.peer_watch's;
here they meet ROS: the heartbeat subscription, the diagnostics publisher, the log, the goal's feedback and result.
"""
from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from msg_defs.action import RunProgram
from msg_defs.msg import DetectorEvent, Heartbeat
from rubber_rig.nodes import awaitables, topics
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes.auth import HEARTBEAT, annotate
from rubber_rig.nodes.draining import create_draining_subscription
from rubber_rig.session.peer_watch import PeerWatch, blind_detectors, program_diagnosis, result_message
from rubber_rig.session.program_watch import Throttle

PEER_CHECK = 0.1           # [s] how often the peers' silences are looked at (named within SILENT + this)
DIAGNOSTICS_PERIOD = 1.0   # [s] /diagnostics at least this often (and at once on news)


class ProgramHealth:
    """The events, silences and detector blindness of the running (or last) program of the excitation ``node``
    (which has ``state``, ``status``, ``session``, ``recording`` and ``clock``).
    """

    def __init__(self, node: Node):
        self.node = node
        self.events: list[DetectorEvent] = []   # detector events of the running (or last) program
        self.blind = ''                  # why the detectors were blind during the running program
        self.feedback_due = Throttle(node.params.feedback_period)
        self.me = node.get_fully_qualified_name()
        self.peers = PeerWatch(self.me)   # the others' silences from their own beats; this node's own stalls
        self.beats = create_draining_subscription(node, Heartbeat, topics.HEARTBEAT, self.on_beat,
                                                  topics.HEARTBEAT_QOS, polled=True)   # read by watch_peers
        self.beat_topic = self.beats.topic_name
        self.pub_diagnostics = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)

    def duties(self) -> dict:
        """What the node's one timer runs for its health (nodes/ticks.py): name -> (period [s], function)."""
        return {'peers': (PEER_CHECK, self.watch_peers), 'diagnostics': (DIAGNOSTICS_PERIOD, self.publish_diagnostics)}

    @property
    def stall(self):
        """This node's own stalls (observed.StallWatch), shared with its program and recorder watches."""
        return self.peers.stall

    def on_beat(self, msg: Heartbeat) -> None:
        now = self.node.clock()
        self.peers.stall.tick(now)
        # only signed beats (nodes/auth.py): a forged one must not hide a silent peer
        if msg.node != self.me and not self.node.auth.refuse(self.node, msg, HEARTBEAT, self.beat_topic):
            self.peers.beat(msg.node, msg.pid, msg.count, conv.to_seconds(msg.header.stamp), now)

    def start_program(self) -> None:
        self.blind, self.events = '', []
        self.peers.start_program(self.node.clock())

    def detectors_blind(self) -> str:
        status = self.node.status
        return blind_detectors(self.node.session, status.sample_rate) if status is not None else ''

    def publish_diagnostics(self) -> None:
        """/diagnostics: the program state and its detector events, named after the node."""
        node = self.node
        running = node.session is not None
        blind = self.detectors_blind()
        if blind and not self.blind:
            node.get_logger().warning(f'detectors blind: {blind}')
        if blind:
            self.blind = blind
        d = program_diagnosis(node.state, node.session.runner.program.name if running else '', self.events, blind,
                              node.recording.lost if running else '', self.peers.silent_now,
                              self.peers.stalled(node.clock()))
        values = dict(d.values, goals_rejected_busy=node.admission.rejected,   # goals rejected while one ran
                      last_goal_rejection=node.admission.last_rejection)
        msg = DiagnosticArray()
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.status.append(annotate(DiagnosticStatus(   # + what it refused unsigned or forged (samples, goals, beats)
            level=DiagnosticStatus.WARN if d.warn else DiagnosticStatus.OK, name=node.get_fully_qualified_name(),
            hardware_id='rubber_rig', message=d.message,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()]), node.auth))
        self.pub_diagnostics.publish(msg)

    def watch_peers(self) -> None:
        """Name a node that went silent (no heartbeat for heartbeat.SILENT, 0.75 s) once per silence in the log;
        while a program runs, remember it for the goal's result. The rig driver's silence ends the program
        elsewhere (status_timeout).
        """
        self.beats.drain()
        news = self.peers.watch(self.node.clock(), self.node.session is not None)
        log = self.node.get_logger()
        if news.stall:
            log.error(f'{self.me} (this node) stalled for {news.stall[1] - news.stall[0]:.1f} s: its callbacks did not '
                      'run; what it did not hear then is no silence of the others')
        for name, age in news.silent.items():
            log.error(f'{name} is silent: no heartbeat for {age:.1f} s (stuck or gone)')
        for name in news.beating_again:
            log.info(f'{name} beats again')
        if news.changed:
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

    def publish_feedback(self, goal_handle, p) -> None:
        """The goal's feedback for the runner's Progress ``p``, at most every feedback_period (node clock)."""
        if self.feedback_due.due(self.node.clock()):
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
        (RecorderWatch.verdict waits at most RESULT_WAIT for the recorder): kept in node.result, logged, and set on
        the goal's future ``done`` (None for a program started without a goal).
        """
        node = self.node
        end_wall, end_sample = node.clock(), session.measured_sequence
        while (words := node.recording.verdict(outcome, end_sample, end_wall, node.clock(),
                                               self.peers.heard(node.recorder_node))) is None:
            await awaitables.sleep(node, 0.02)
        node.result = result = self.result(session.runner, success, ended, words)
        node.get_logger().info(f'program ended: {result.message}')
        if done is not None and not done.done():
            done.set_result(result)

    def result(self, runner, success: bool, ended: bool, recording: str = '') -> RunProgram.Result:
        """The goal's result for the program of ``runner``: a success only if asked for and it was not aborted
        (or it ``ended`` by an end-of-test trigger), with the block summaries, the events and what else happened
        (the recording's words ``recording`` among them).
        """
        message = result_message(runner.abort_reason if runner.aborted else 'completed', self.blind, recording,
                                 self.node.recording.lost, self.peers.words(self.node.clock()))
        return RunProgram.Result(success=success and (ended or not runner.aborted), message=message,
                                 blocks=[conv.block_summary_msg(s) for s in runner.block_summaries],
                                 events=list(self.events))
