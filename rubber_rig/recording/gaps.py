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

"""Sequence-gap accounting for the rig's sample streams: lost samples are counted, never silent, and
nothing that was not lost is counted as lost.

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

A smaller start means the stream restarted (counted separately). When the restarted publisher's first message
is not its first publication, the samples it numbered before that message were published before the recorder
matched it: lost.
"""
from dataclasses import dataclass, field

# message type -> (sequence field, array field whose length is the number of samples, or None for 1)
SEQUENCED_TYPES = {
    'msg_defs/msg/RigSampleBatch': ('first_sequence', 'displacement'),
    'msg_defs/msg/SetpointBatch': ('first_sequence', 'displacement'),
    'msg_defs/msg/ModelPrediction': ('first_sequence', 'displacement'),
    'msg_defs/msg/RigSample': ('sequence', None),
}
# message types whose ``frames_lost`` field counts samples the driver lost on the bus before the message
FRAMES_LOST_TYPES = ('msg_defs/msg/RigSampleBatch',)
MAX_EVENTS = 1000     # keep the first events in detail; the totals always count all of them
PUBSEQ_MOD = 1 << 32  # MCAP stores the publication sequence number in 32 bits


def _get(msg, name):
    if isinstance(msg, dict):
        return msg.get(name)
    return getattr(msg, name, None)


def sequence_span(msg_type: str, msg):
    """(first sequence, sample count) of a sequenced message, or None for other types."""
    spec = SEQUENCED_TYPES.get(msg_type)
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

    def _lose(self, topic, n):
        self.samples_lost += n
        self.lost_by_topic[topic] = self.lost_by_topic.get(topic, 0) + n

    def observe(self, topic: str, first: int, count: int, log_time_ns: int = 0, *, frames_lost: int = 0,
                publication_sequence: int = None):
        """Account one message; returns the event dict if it revealed a gap, a jump or a restart.

        ``frames_lost``: samples the publisher reports lost before this message (always counted);
        ``publication_sequence``: the DDS publication sequence number (None or 0: unknown).
        """
        self.samples_seen += count
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
                     'lost': frames_lost, 'frames_lost': frames_lost, 'log_time_ns': int(log_time_ns)}
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
                     'received': first, 'lost': lost, 'frames_lost': frames_lost,
                     'log_time_ns': int(log_time_ns)}
        else:
            self.restarts += 1
            # a new publisher (a restarted rig numbers its samples from 0 again) whose first message reached us
            # after others it had published (its DDS publication sequence starts at 1): the samples before this
            # one, 0..first-1, were published before we matched it, so they are lost, not merely unseen
            missed = first if pub is not None and pub > 1 and first > 0 else 0
            if missed:
                self._lose(topic, missed)
                self.gaps += 1
            event = {'topic': topic, 'kind': 'gap' if missed else 'restart', 'restart': True, 'expected': expected,
                     'received': first, 'lost': frames_lost + missed, 'frames_lost': frames_lost,
                     'log_time_ns': int(log_time_ns)}
        if len(self.events) < MAX_EVENTS:
            self.events.append(event)
        return event

    def observe_message(self, topic: str, msg_type: str, msg, log_time_ns: int = 0,
                        publication_sequence: int = None):
        """Account one decoded message (one of another type than SEQUENCED_TYPES is ignored: None)."""
        span = sequence_span(msg_type, msg)
        if span is None:
            return None
        return self.observe(topic, span[0], span[1], log_time_ns, frames_lost=frames_lost_of(msg_type, msg),
                            publication_sequence=publication_sequence)

    def summary(self) -> dict:
        return {'sequence_gaps': self.gaps, 'samples_lost': self.samples_lost,
                'sequence_restarts': self.restarts, 'sequence_jumps': self.jumps,
                'samples_skipped': self.samples_skipped, 'frames_lost': self.frames_lost,
                'samples_seen': self.samples_seen, 'samples_lost_by_topic': dict(self.lost_by_topic)}
