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

"""What the excitation node knows of the recorder: whether this namespace's samples are being recorded (a
program with require_recording starts only then) and what happened to the recording a program started in (the
ROS-free recording.outcome decides: complete, lost from sample N and why, not recorded; a split into the
next part is the same recording).

The recorder publishes its status (recorder_status, latched) every 0.5 s; a status older than ``timeout`` [s]
means the recorder is gone. A restarted recorder or rig_driver is a new publisher on its topic: a status from
before that change speaks for the old one and does not count.
"""
from __future__ import annotations

from rclpy.node import Node

from msg_defs.msg import RecorderStatus
from rubber_rig.nodes import topics
from rubber_rig.recording.outcome import RecorderReport, RecordingOutcome

STATES = {RecorderStatus.STATE_IDLE: 'idle', RecorderStatus.STATE_RECORDING: 'recording',
          RecorderStatus.STATE_ERROR: 'error'}
RESULT_WAIT = 0.75     # [s] a program's result waits at most this long after its end for word from the recorder


class RecordingWatch:
    """The latest recorder status for ``node`` and what it means for the program that runs (its RecordingOutcome:
    complete, lost from sample N and why, not recorded; a split is the same recording).
    """

    def __init__(self, node: Node, require: bool, timeout: float):
        self.node, self.require, self.timeout = node, require, timeout
        self.status: RecorderStatus | None = None
        self.wall = 0.0                  # node clock [s] of the latest status
        self.outcome = RecordingOutcome(timeout)   # of the running (or last) program
        self.ended: list[RecordingOutcome] = []    # of programs that ended and whose result waits for the recorder
        self.recorder_node = ''          # fully qualified name of the recorder publishing the status (heartbeats)
        # endpoint gids of the publishers of a topic and when they last changed (a node restarted)
        self._publisher_sets: dict[str, tuple[frozenset, float]] = {}

    @property
    def samples_topic(self) -> str:
        return f'{self.node.get_namespace().rstrip("/")}/{topics.SAMPLES}'

    @property
    def age(self) -> float:
        """Seconds since the latest recorder status, counting only time this node ran (StallWatch)."""
        return self.node.health.stall.since(self.wall, self.node.clock())

    @property
    def recorded_by(self) -> str:
        return self.outcome.recorded_by

    @property
    def lost(self) -> str:
        return self.outcome.lost

    def report(self) -> RecorderReport | None:
        r = self.status
        if r is None:
            return None
        return RecorderReport(self.wall, STATES.get(r.state, r.state_name), r.path, r.error,
                              self.samples_topic in r.topics, int(r.samples_lost))

    def on_status(self, msg: RecorderStatus, session) -> str:
        """A recorder status while ``session`` (a ProgramSession, or None) runs: why it must stop, or ''."""
        self.status, self.wall = msg, self.node.clock()
        self._name_recorder()
        report = self.report()
        for outcome in self.ended:
            outcome.latest = report
        if session is None:
            return ''
        measured = session.next_sample is not None
        if self.require and self.failed:
            self.outcome.observe(report, session.measured_sequence, measured)
            return f'recording failed: {msg.error or "recorder error"}'
        if self.outcome.observe(report, session.measured_sequence, measured):
            self.node.get_logger().error(self.outcome.lost)
        return ''

    def _name_recorder(self) -> None:
        ns = self.node.get_namespace().rstrip('/')
        infos = self.node.get_publishers_info_by_topic(f'{ns}/{topics.RECORDER_STATUS}')
        if infos:
            i = infos[0]
            self.recorder_node = f'{i.node_namespace.rstrip("/")}/{i.node_name}'

    @property
    def failed(self) -> bool:
        return self.status is not None and self.status.state == RecorderStatus.STATE_ERROR

    def start_program(self) -> None:
        """A program starts: a new outcome, from the recording it starts in."""
        self.outcome = RecordingOutcome(self.timeout, self.samples_topic)
        self.outcome.start(self.report(), self.node.clock(), self.node.health.stall.resumed_at)

    def path(self) -> str:
        """The file the recorder reports recording this namespace's samples into ('' if none, or stale)."""
        r = self.status
        if r is None or self.age > self.timeout or r.state != RecorderStatus.STATE_RECORDING \
                or self.samples_topic not in r.topics:
            return ''
        return r.path or '(unnamed file)'

    def check(self, next_sample) -> None:
        """A program that started while being recorded and whose recorder went silent says so, once: in the log,
        the diagnostics and the goal's result (without require_recording the program runs on; with it, the node
        stops it). The silence counts only while this node ran: a stall of its own is not the recorder's.
        """
        if self.outcome.check(self.node.clock(), next_sample, self.node.health.stall.resumed_at):
            self.node.get_logger().error(self.outcome.lost)

    def end_program(self) -> RecordingOutcome:
        """The running program ended: its outcome waits for word from the recorder (verdict)."""
        outcome = self.outcome
        self.ended.append(outcome)
        return outcome

    def verdict(self, outcome: RecordingOutcome, end_sample: int, ended: float, beats) -> str | None:
        """The result's words on `outcome`'s recording (None: wait). The recorder's heartbeat after the end with its
        latest status recording the same files confirms it (a status comes every 0.5 s, a heartbeat every 0.25 s).
        """
        now = self.node.clock()
        beat = beats.last.get(self.recorder_node) if self.recorder_node else None
        words = outcome.verdict(now, end_sample, ended, self.node.health.stall.resumed_at,
                                heard=beat.received if beat is not None else None, wait=RESULT_WAIT)
        if words is not None and outcome in self.ended:
            self.ended.remove(outcome)
        return words

    def fresh(self, since: float) -> bool:
        """The recorder status (with require_recording) is ready to judge a goal that arrived at ``since``
        (the node clock). An error counts only if reported since then: the error of a recorder that was just
        replaced must not refuse a goal the new one would record.
        """
        return not self.require or (
            self.status is not None and self.age <= self.timeout
            and ((self.failed and self.wall >= since) or self.ready() == ''))

    def _publishers_changed(self, topic: str) -> tuple[int, float]:
        """(number of publishers of ``topic``, node clock [s] when that set of publishers last changed)."""
        gids = frozenset(bytes(i.endpoint_gid) for i in self.node.get_publishers_info_by_topic(topic))
        known, since = self._publisher_sets.get(topic, (None, 0.0))
        if gids != known:
            since = self.node.clock()
            self._publisher_sets[topic] = (gids, since)
        return len(gids), since

    def ready(self) -> str:
        """'' when a program may start as far as the recording goes, else why not."""
        if not self.require:
            return ''
        r = self.status
        if r is None:
            return "require_recording: no recorder status on 'recorder_status' (is the recorder running?)"
        if self.age > self.timeout:
            return f'require_recording: no recorder status for {self.age:.1f} s'
        # a restarted recorder is a new publisher of its status: the last status of the one it replaced
        # (latched, fresh for recorder_timeout) must not stand for it
        ns = self.node.get_namespace().rstrip('/')
        _, since = self._publishers_changed(f'{ns}/{topics.RECORDER_STATUS}')
        if self.wall <= since:
            return 'require_recording: waiting for a status of the recorder that runs now (it was restarted)'
        if r.state != RecorderStatus.STATE_RECORDING:
            return f'require_recording: the recorder is {r.state_name}' + (f': {r.error}' if r.error else '')
        if self.samples_topic not in r.topics:
            return f'require_recording: the recorder does not record {self.samples_topic} yet'
        # a restarted rig_driver is a new publisher: until the recorder has matched it, its first samples
        # would be published to nobody and not even counted lost (the recorder never sees them). A recorder
        # status from before the publishers changed counts the old ones: wait for a newer one
        known, since = self._publishers_changed(self.samples_topic)
        if self.wall <= since:
            return (f'require_recording: waiting for a recorder status newer than the last change of '
                    f'{self.samples_topic} publishers')
        matched = (r.topic_publishers[r.topics.index(self.samples_topic)]
                   if len(r.topic_publishers) == len(r.topics) else known)
        if matched < known:
            return (f'require_recording: the recorder is matched with {matched} of the {known} publishers of '
                    f'{self.samples_topic} (it has not discovered the restarted rig_driver yet)')
        return ''
