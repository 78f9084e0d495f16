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

"""What the excitation knows of the recorder, ROS-free, on an injected clock: whether this namespace's samples are
recorded (a program with require_recording starts only then), whether the recorder is gone (a running program with
require_recording stops) and what happened to the recording a program started in (recording.outcome decides:
complete, lost from sample N and why, not recorded; a split into the next part is the same recording).

The recorder publishes its status (recorder_status, latched) every 0.5 s; one older than ``timeout`` [s], counted
only while this node ran (observed.StallWatch), means the recorder is gone. A restarted recorder or rig_driver is a
new publisher on its topic (the node passes the graph's publisher endpoints of each topic as plain values): a status
received before that change speaks for the old one and does not count.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from ..recording.outcome import RecorderReport, RecordingOutcome
from .observed import StallWatch

RESULT_WAIT = 0.75     # [s] a program's result waits at most this long after its end for word from the recorder


@dataclass
class RecorderView:
    """A recorder status (msg_defs/RecorderStatus) as plain values: ``state`` 'idle', 'recording' or 'error';
    ``topics`` the topics it records matched with ``topic_publishers`` publishers each.
    """

    state: str
    path: str = ''
    error: str = ''
    topics: list = field(default_factory=list)
    topic_publishers: list = field(default_factory=list)
    samples_lost: int = 0


class PublisherChanges:
    """When the set of publishers of each topic last changed (a node restarted): the endpoints the graph shows now,
    fed each time a rule asks.
    """

    def __init__(self):
        self._sets: dict[str, tuple[frozenset, float]] = {}

    def changed_at(self, topic: str, publishers: frozenset, now: float) -> float:
        """[s] when the publishers of ``topic`` became ``publishers`` (``now`` if they just did)."""
        known, since = self._sets.get(topic, (None, 0.0))
        if publishers != known:
            since = now
            self._sets[topic] = (frozenset(publishers), since)
        return since


class RecorderWatch:
    """The latest recorder status and what it means for the running program (module doc).

    Parameters
    ----------
    require : bool
        require_recording: a program starts only while the samples are recorded and stops when the recorder fails.
    timeout : float
        [s] recorder_timeout: a recorder without a status for this long is gone.
    samples_topic : str
        This namespace's samples topic (fully qualified): what must be recorded.
    recorder_topic : str
        The recorder status topic (fully qualified): a restarted recorder is a new publisher on it.
    stall : StallWatch
        This node's own stalls: the recorder's silence counts only while the node ran.
    """

    def __init__(self, require: bool, timeout: float, samples_topic: str, recorder_topic: str, stall: StallWatch):
        self.require, self.timeout, self.stall = bool(require), float(timeout), stall
        self.samples_topic, self.recorder_topic = samples_topic, recorder_topic
        self.status: Optional[RecorderView] = None
        self.received = 0.0                          # [s] the latest status
        self.outcome = RecordingOutcome(self.timeout)   # of the running (or last) program
        self.ended: list[RecordingOutcome] = []      # of programs that ended and whose result waits for the recorder
        self.publishers = PublisherChanges()

    def age(self, now: float) -> float:
        """[s] since the latest recorder status, counting only time this node ran."""
        return self.stall.since(self.received, now)

    @property
    def lost(self) -> str:
        return self.outcome.lost

    @property
    def failed(self) -> bool:
        return self.status is not None and self.status.state == 'error'

    def report(self) -> Optional[RecorderReport]:
        r = self.status
        if r is None:
            return None
        return RecorderReport(self.received, r.state, r.path, r.error, self.samples_topic in r.topics,
                              int(r.samples_lost))

    def on_status(self, status: RecorderView, now: float, next_sample: Optional[int] = None,
                  measured: bool = False) -> tuple[str, str]:
        """A recorder status received at ``now`` while a program runs (``next_sample``: the sample it expects next,
        None when none runs; ``measured``: its first sample was measured). Returns (why the program must stop, the
        loss this status revealed), each '' for none.
        """
        self.status, self.received = status, now
        report = self.report()
        for outcome in self.ended:
            outcome.latest = report
        if next_sample is None:
            return '', ''
        if self.require and self.failed:
            self.outcome.observe(report, next_sample, measured)
            return f'recording failed: {status.error or "recorder error"}', ''
        return '', self.outcome.observe(report, next_sample, measured)

    def start_program(self, now: float) -> None:
        """A program starts: a new outcome, from the recording it starts in."""
        self.outcome = RecordingOutcome(self.timeout, self.samples_topic)
        self.outcome.start(self.report(), now, self.stall.resumed_at)

    def check(self, now: float, next_sample: int) -> str:
        """The loss of a recording whose recorder went silent, the first time this check finds it ('' otherwise):
        said once, in the log, the diagnostics and the goal's result.
        """
        return self.outcome.check(now, next_sample, self.stall.resumed_at)

    def why_stop(self, now: float) -> str:
        """With require_recording: why the running program must stop (the recorder is gone), else ''."""
        age = self.age(now)
        if self.require and age > self.timeout:
            return f'recording lost: no recorder status for {age:.1f} s (the recorder is gone)'
        return ''

    def end_program(self) -> RecordingOutcome:
        """The running program ended: its outcome waits for word from the recorder (:meth:`verdict`)."""
        outcome = self.outcome
        self.ended.append(outcome)
        return outcome

    def verdict(self, outcome: RecordingOutcome, end_sample: int, ended: float, now: float,
                heard: Optional[float] = None) -> Optional[str]:
        """The result's words on ``outcome``'s recording (None: wait). ``heard``: when the recorder's latest heartbeat
        was received (None: never); one after the end with its latest status recording the same files confirms it (a
        status comes every 0.5 s, a heartbeat every 0.25 s).
        """
        words = outcome.verdict(now, end_sample, ended, self.stall.resumed_at, heard=heard, wait=RESULT_WAIT)
        if words is not None and outcome in self.ended:
            self.ended.remove(outcome)
        return words

    def fresh(self, since: float, now: float, recorder_publishers: frozenset, sample_publishers: frozenset) -> bool:
        """The recorder status (with require_recording) is ready to judge a goal that arrived at ``since``. An error
        counts only if reported since then: the error of a recorder that was just replaced must not refuse a goal
        the new one would record.
        """
        return not self.require or (
            self.status is not None and self.age(now) <= self.timeout
            and ((self.failed and self.received >= since)
                 or self.why_not_start(now, recorder_publishers, sample_publishers) == ''))

    def why_not_start(self, now: float, recorder_publishers: frozenset, sample_publishers: frozenset) -> str:
        """'' when a program may start as far as the recording goes, else why not. ``recorder_publishers`` and
        ``sample_publishers``: the endpoints (any hashable ids) the graph shows publishing the recorder status and
        the samples.
        """
        if not self.require:
            return ''
        r = self.status
        if r is None:
            return "require_recording: no recorder status on 'recorder_status' (is the recorder running?)"
        age = self.age(now)
        if age > self.timeout:
            return f'require_recording: no recorder status for {age:.1f} s'
        # a restarted recorder is a new publisher of its status: the last status of the one it replaced (latched,
        # fresh for recorder_timeout) must not stand for it
        if self.received <= self.publishers.changed_at(self.recorder_topic, recorder_publishers, now):
            return 'require_recording: waiting for a status of the recorder that runs now (it was restarted)'
        if r.state != 'recording':
            return f'require_recording: the recorder is {r.state}' + (f': {r.error}' if r.error else '')
        if self.samples_topic not in r.topics:
            return f'require_recording: the recorder does not record {self.samples_topic} yet'
        # a restarted rig_driver is a new publisher: until the recorder has matched it, its first samples would be
        # published to nobody and not even counted lost (the recorder never sees them). A recorder status from
        # before the publishers changed counts the old ones: wait for a newer one
        if self.received <= self.publishers.changed_at(self.samples_topic, sample_publishers, now):
            return (f'require_recording: waiting for a recorder status newer than the last change of '
                    f'{self.samples_topic} publishers')
        known = len(sample_publishers)
        matched = (r.topic_publishers[r.topics.index(self.samples_topic)]
                   if len(r.topic_publishers) == len(r.topics) else known)
        if matched < known:
            return (f'require_recording: the recorder is matched with {matched} of the {known} publishers of '
                    f'{self.samples_topic} (it has not discovered the restarted rig_driver yet)')
        return ''
