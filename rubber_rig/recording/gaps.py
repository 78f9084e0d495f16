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

"""The loss ledger of a recording: one rule, used by the recorder while it writes (gapcheck, session), by
``load_recording`` (``rubber-rig info``, the bench summary) and by ``recover``, so that they agree to the sample.

What is counted: the samples of the rig's sample stream, the one topic of RigSampleBatch (or RigSample) messages
chosen by :func:`sample_topic` (the reader's arrays hold the same topic). Setpoints and model predictions also
carry sample sequence numbers, but they are not samples: their numbers index the rig's samples they are for, so
a setpoint stream that starts again below its last number (a held program resumed, a restarted rig driver) or a
prediction stream that skips a batch says nothing about samples lost. They are not in the ledger.

The messages are taken in file order (the order the recorder wrote them; a reader must not re-sort them by log
time for this), per topic, and each is accounted by :class:`GapTracker`:

A batch message carries ``first_sequence`` and N samples; the next batch of an unbroken stream starts
at ``first_sequence + N``. A larger start is a *gap*; what the skipped samples were decides the count:

- samples the rig driver reports lost on the bus (RigSampleBatch ``frames_lost``, set on the batch after
  the loss): lost, always;
- the rest of the gap, when the DDS publication sequence number of the message also skipped (messages
  published but never received, in transport or by the recorder): lost;
- the rest of the gap, when the publication sequence number is contiguous (the publisher sent nothing
  in between: the rig idled between two programs and the next one starts at a later sample): a *jump*,
  counted separately, not a loss;
- when no publication sequence number is known (data written without one, foreign recordings): lost
  (the conservative reading).

The publication sequence number is the one the file stores (32 bits) on a channel whose ``rubber_rig.sequence``
is ``publication``; the recorder uses the same stored value, so writing and reading see the same numbers.

A smaller start means the stream may have restarted; the next message decides (:class:`StrayOrRestart`, the one
rule the element model follows too): a restart if it continues the message that went back or does not go on
where the stream was; a *stray* (stale or foreign: another publisher, a late copy) if the stream goes on where
it was, perhaps after a gap, and then the stray is taken back out of the counts. A restart is counted separately.
When the restarted publisher's first message is not its first publication, the samples it numbered before that
message were published before the recorder matched it: lost. (This rule holds for the sample stream only: a
restarted rig driver numbers its samples from 0.)
"""
from dataclasses import dataclass, field

BATCH = 'msg_defs/msg/RigSampleBatch'
SAMPLE = 'msg_defs/msg/RigSample'
# the sample streams: message type -> (sequence field, array field whose length is the number of samples, or None
# for 1). SetpointBatch and ModelPrediction are not here on purpose (module docstring).
SAMPLE_TYPES = {
    BATCH: ('first_sequence', 'displacement'),
    SAMPLE: ('sequence', None),
}
# message types whose ``frames_lost`` field counts samples the driver lost on the bus before the message
FRAMES_LOST_TYPES = (BATCH,)
MAX_EVENTS = 1000     # keep the first events in detail; the totals always count all of them
PUBSEQ_MOD = 1 << 32  # MCAP stores the publication sequence number in 32 bits
COUNTS = ('sequence_gaps', 'samples_lost', 'sequence_restarts', 'sequence_jumps', 'samples_skipped', 'frames_lost',
          'samples_seen', 'sequence_strays')


def _get(msg, name):
    if isinstance(msg, dict):
        return msg.get(name)
    return getattr(msg, name, None)


def sample_topic(topic_types: dict):
    """The recording's sample stream among ``topic_types`` (topic -> message type): of the RigSampleBatch topics
    the one whose last name part is ``samples``, else the first by name; without any, the same among RigSample
    topics; None if there is no sample topic. The reader's arrays and the loss ledger use this one choice.
    """
    for msg_type in (BATCH, SAMPLE):
        candidates = sorted(t for t, ty in topic_types.items() if ty == msg_type)
        for topic in candidates:
            if topic.rstrip('/').split('/')[-1] == 'samples':
                return topic
        if candidates:
            return candidates[0]
    return None


def sequence_span(msg_type: str, msg):
    """(first sequence, sample count) of a sample message (SAMPLE_TYPES), or None for other types."""
    spec = SAMPLE_TYPES.get(msg_type)
    if spec is None:
        return None
    seq_field, array_field = spec
    first = _get(msg, seq_field)
    if first is None:
        return None
    if array_field is None:
        return int(first), 1
    samples = _get(msg, array_field)
    count = 0 if samples is None else len(samples)
    return int(first), count


def frames_lost_of(msg_type: str, msg) -> int:
    if msg_type not in FRAMES_LOST_TYPES:
        return 0
    return int(_get(msg, 'frames_lost') or 0)


def stamp_ns_of(msg) -> int:
    """The header stamp of a message [ns] (0 without one): for a sample batch, the time of its first sample."""
    stamp = _get(_get(msg, 'header'), 'stamp')
    if stamp is None:
        return 0
    return int(_get(stamp, 'sec') or 0) * 1_000_000_000 + int(_get(stamp, 'nanosec') or 0)


RESTART, STRAY = 'restart', 'stray'


def stray_or_restart(back_first: int, back_count: int, expected: int, next_first: int) -> str:
    """What a message that went back was, told by the next one of its topic (sequence numbers of samples).

    back_first, back_count: the message that went back (its first sequence and number of samples); expected: the
    sequence its stream expected next when it came (> back_first); next_first: the first sequence of the message
    after it. RESTART when the next one continues it (a restarted rig driver numbers from 0 again and goes on)
    or goes neither on from it nor on where the stream was; STRAY when the stream goes on where it was (at
    ``expected`` or after it: a gap of the old stream, not a new one) - the message was stale or foreign.
    """
    if next_first == back_first + back_count:
        return RESTART
    return STRAY if next_first >= expected else RESTART


class StrayOrRestart:
    """The one message of a stream that went back, held until the next message says what it was
    (:func:`stray_or_restart`). ``payload``: whatever the caller must keep to act on the verdict.
    """

    def __init__(self):
        self.pending = None               # (back_first, back_count, expected, payload) or None

    def went_back(self, first: int, count: int, expected: int, payload=None) -> None:
        """A message of ``count`` samples from ``first`` came while ``expected`` was due (first < expected)."""
        self.pending = (int(first), int(count), int(expected), payload)

    def judge(self, next_first: int):
        """(verdict, payload) for the held message given the next one's first sequence, or None when none is
        held; the held message is released either way.
        """
        if self.pending is None:
            return None
        first, count, expected, payload = self.pending
        self.pending = None
        return stray_or_restart(first, count, expected, next_first), payload


class StreamOrder:
    """What a live consumer of a sample stream (the element model) does with each batch, by the one rule of
    :func:`stray_or_restart`: a batch that goes back from the sequence ``expected`` next is held (not taken) until the
    next batch says whether it was a restart (then the consumer starts afresh from the held batch) or a stray (stale
    or foreign: dropped and counted in ``strays``).
    """

    def __init__(self):
        self.held = StrayOrRestart()
        self.strays = 0

    def arrive(self, first: int, count: int, expected, payload=None):
        """A batch of ``count`` samples from ``first`` while the consumer expects ``expected`` next (None: nothing
        yet). Returns (verdict, take): verdict on the batch held before, None or (RESTART | STRAY, its payload) - on
        a restart the consumer restarts and takes that payload first -, and whether to take this batch now (False:
        it went back and is held).
        """
        verdict = self.held.judge(first)
        if verdict is not None:
            kind, (held_first, held_count, held_payload) = verdict
            if kind == RESTART:
                expected = held_first + held_count     # the consumer goes on from the restarted stream's batch
            else:
                self.strays += 1
            verdict = (kind, held_payload)
        if expected is not None and first < expected:
            self.held.went_back(first, count, expected, (first, count, payload))
            return verdict, False
        return verdict, True


@dataclass
class GapTracker:
    """Per-topic continuity of sequence numbers across messages (and across split files)."""

    next_expected: dict = field(default_factory=dict)
    last_pubseq: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    gaps: int = 0
    samples_lost: int = 0
    restarts: int = 0
    jumps: int = 0
    samples_skipped: int = 0          # sequence jumps that are not loss (nothing was published)
    frames_lost: int = 0              # of samples_lost: reported by the driver (bus)
    samples_seen: int = 0
    lost_by_topic: dict = field(default_factory=dict)
    strays: int = 0                   # messages that went back and were not followed (stale or foreign)
    _went_back: dict = field(default_factory=dict)   # topic -> StrayOrRestart holding what its message changed

    def _undo_stray(self, topic: str, changed) -> None:
        """The message that went back was not followed by its own stream but by the one it interrupted: it was
        stale or foreign (another publisher, a late copy), not a restart. Its restart and any loss it implied
        are taken back, and the stream is judged as if it had not come.
        """
        expected, prev_pub, event, lost, frames = changed
        self.restarts -= 1
        self.strays += 1
        if lost:
            self.gaps -= 1
            self.samples_lost -= lost
            self.lost_by_topic[topic] -= lost
            self.frames_lost -= frames
        event.update(kind='stray', lost=0, frames_lost=0)
        event.pop('restart', None)
        self.next_expected[topic], self.last_pubseq[topic] = expected, prev_pub

    def _lose(self, topic, n):
        self.samples_lost += n
        self.lost_by_topic[topic] = self.lost_by_topic.get(topic, 0) + n

    def observe(self, topic: str, first: int, count: int, log_time_ns: int = 0, *, frames_lost: int = 0,
                publication_sequence: int = None, stamp_ns: int = 0):
        """Account one message; returns the event dict if it revealed a gap, a jump or a restart.

        ``frames_lost``: samples the publisher reports lost before this message (always counted);
        ``publication_sequence``: the DDS publication sequence number (None or 0: unknown); ``log_time_ns``: when
        it was recorded; ``stamp_ns``: its header stamp (the rig time of its first sample). Events carry both.
        """
        self.samples_seen += count
        verdict = self._went_back[topic].judge(first) if topic in self._went_back else None
        if verdict is not None and verdict[0] == STRAY:
            self._undo_stray(topic, verdict[1])
        expected = self.next_expected.get(topic)
        self.next_expected[topic] = first + count
        prev_pub = self.last_pubseq.get(topic)
        pub = int(publication_sequence) if publication_sequence else None
        self.last_pubseq[topic] = pub
        frames_lost = max(0, int(frames_lost or 0))
        if frames_lost:
            self.frames_lost += frames_lost
            self._lose(topic, frames_lost)
        if expected is None or first == expected:
            if not frames_lost:
                return None
            event = {'topic': topic, 'kind': 'gap', 'expected': first - frames_lost, 'received': first,
                     'lost': frames_lost, 'frames_lost': frames_lost}
            self.gaps += 1
        elif first > expected:
            rest_lost = rest = max(0, first - expected - frames_lost)
            if rest and pub is not None and prev_pub is not None:
                step = (pub - prev_pub) % PUBSEQ_MOD
                if step <= 1 or step >= PUBSEQ_MOD // 2:   # contiguous (or a new publisher): none missed
                    rest_lost = 0
                    self.jumps += 1
                    self.samples_skipped += rest
            if rest_lost:
                self._lose(topic, rest_lost)
            lost = frames_lost + rest_lost
            if lost:
                self.gaps += 1
            event = {'topic': topic, 'kind': 'gap' if lost else 'jump', 'expected': expected,
                     'received': first, 'lost': lost, 'frames_lost': frames_lost}
        else:
            self.restarts += 1
            # a new publisher (a restarted rig numbers its samples from 0 again) whose first message reached us
            # after others it had published (its DDS publication sequence starts at 1): the samples before this
            # one, 0..first-1, were published before we matched it, so they are lost, not merely unseen. The same
            # publisher going on without a skip (publication sequence +1) published nothing in between: none lost.
            same_publisher = pub is not None and prev_pub is not None and (pub - prev_pub) % PUBSEQ_MOD == 1
            missed = first if pub is not None and pub > 1 and first > 0 and not same_publisher else 0
            if missed:
                self._lose(topic, missed)
            lost = frames_lost + missed
            if lost:
                self.gaps += 1
            event = {'topic': topic, 'kind': 'gap' if lost else 'restart', 'restart': True, 'expected': expected,
                     'received': first, 'lost': lost, 'frames_lost': frames_lost}
            self._went_back.setdefault(topic, StrayOrRestart()).went_back(
                first, count, expected, (expected, prev_pub, event, lost, frames_lost))
        event['log_time_ns'], event['stamp_ns'] = int(log_time_ns), int(stamp_ns)
        if len(self.events) < MAX_EVENTS:
            self.events.append(event)
        return event

    def observe_message(self, topic: str, msg_type: str, msg, log_time_ns: int = 0,
                        publication_sequence: int = None):
        """Account one decoded message (one of another type than SAMPLE_TYPES is ignored: None)."""
        span = sequence_span(msg_type, msg)
        if span is None:
            return None
        return self.observe(topic, span[0], span[1], log_time_ns, frames_lost=frames_lost_of(msg_type, msg),
                            publication_sequence=publication_sequence, stamp_ns=stamp_ns_of(msg))

    def summary(self) -> dict:
        return dict(_counts(self), samples_lost_by_topic=dict(self.lost_by_topic))


class LossLedger:
    """The loss of a recording, as the recorder, ``load_recording`` (info, bench) and ``recover`` all count it.

    Feed it every message of the recording in file order (:meth:`observe`; types other than SAMPLE_TYPES are
    ignored, so the caller need not filter); each sample topic has its own :class:`GapTracker`, and the counts are
    those of the sample stream (:func:`sample_topic`). ``publication_sequence``: the sequence the file stores for
    the message if its channel stores publication sequence numbers (``rubber_rig.sequence: publication``), else
    None.
    """

    def __init__(self):
        self.trackers = {}                 # sample topic -> its GapTracker
        self.types = {}                    # sample topic -> message type

    def observe(self, topic: str, msg_type: str, msg, log_time_ns: int = 0, publication_sequence: int = None):
        """Account one decoded message; the gap, jump or restart event it revealed, or None."""
        if msg_type not in SAMPLE_TYPES:
            return None
        tracker = self.trackers.get(topic)
        if tracker is None:
            tracker = self.trackers[topic] = GapTracker()
            self.types[topic] = msg_type
        return tracker.observe_message(topic, msg_type, msg, log_time_ns, publication_sequence)

    @property
    def topic(self):
        """The sample stream whose samples are counted (None before any sample message)."""
        return sample_topic(self.types)

    @property
    def tracker(self) -> GapTracker:
        return self.trackers.get(self.topic) or GapTracker()

    @property
    def samples_lost(self) -> int:
        return self.tracker.samples_lost

    @property
    def sequence_gaps(self) -> int:
        return self.tracker.gaps

    @property
    def events(self) -> list:
        """The first MAX_EVENTS gap, jump and restart events of the sample stream."""
        return self.tracker.events

    @property
    def next_expected(self) -> dict:
        """Sample topic -> the sequence its next message continues at."""
        return {topic: t.next_expected[topic] for topic, t in self.trackers.items() if topic in t.next_expected}

    def counts(self) -> dict:
        """Per sample topic: its counts (COUNTS), for the difference between two points of a recording."""
        return {topic: _counts(t) for topic, t in self.trackers.items()}

    def summary(self, since: dict = None) -> dict:
        """The ledger: COUNTS of the sample stream and ``sample_topic``; ``since`` (an earlier :meth:`counts`): only
        what was added after it (a file of a split recording).
        """
        topic = self.topic
        now = _counts(self.tracker)
        before = (since or {}).get(topic, dict.fromkeys(COUNTS, 0))
        return {'sample_topic': topic or '', **{key: now[key] - before[key] for key in COUNTS}}


def _counts(tracker: GapTracker) -> dict:
    return {'sequence_gaps': tracker.gaps, 'samples_lost': tracker.samples_lost,
            'sequence_restarts': tracker.restarts, 'sequence_jumps': tracker.jumps,
            'samples_skipped': tracker.samples_skipped, 'frames_lost': tracker.frames_lost,
            'samples_seen': tracker.samples_seen, 'sequence_strays': tracker.strays}
