"""Sequence-gap accounting for the rig's sample streams: lost samples are counted, never silent.

A batch message carries ``first_sequence`` and N samples; the next batch of an unbroken stream starts
at ``first_sequence + N``. A larger start means samples were lost between the batches (bus, rig driver
or DDS); a smaller one means the stream restarted (counted separately, not as loss).
"""
from dataclasses import dataclass, field

# message type -> (sequence field, array field whose length is the number of samples, or None for 1)
SEQUENCED_TYPES = {
    'msg_defs/msg/RigSampleBatch': ('first_sequence', 'displacement'),
    'msg_defs/msg/SetpointBatch': ('first_sequence', 'displacement'),
    'msg_defs/msg/ModelPrediction': ('first_sequence', 'displacement'),
    'msg_defs/msg/RigSample': ('sequence', None),
}
MAX_EVENTS = 1000     # keep the first events in detail; the totals always count all of them


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


@dataclass
class GapTracker:
    """Per-topic continuity of sequence numbers across messages (and across split files)."""
    next_expected: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    gaps: int = 0
    samples_lost: int = 0
    restarts: int = 0
    samples_seen: int = 0
    lost_by_topic: dict = field(default_factory=dict)

    def observe(self, topic: str, first: int, count: int, log_time_ns: int = 0):
        """Account one message; returns the event dict if it revealed a gap or a restart."""
        self.samples_seen += count
        expected = self.next_expected.get(topic)
        self.next_expected[topic] = first + count
        if expected is None or first == expected:
            return None
        if first > expected:
            lost = first - expected
            self.gaps += 1
            self.samples_lost += lost
            self.lost_by_topic[topic] = self.lost_by_topic.get(topic, 0) + lost
            event = {'topic': topic, 'kind': 'gap', 'expected': expected, 'received': first,
                     'lost': lost, 'log_time_ns': int(log_time_ns)}
        else:
            self.restarts += 1
            event = {'topic': topic, 'kind': 'restart', 'expected': expected, 'received': first,
                     'lost': 0, 'log_time_ns': int(log_time_ns)}
        if len(self.events) < MAX_EVENTS:
            self.events.append(event)
        return event

    def observe_message(self, topic: str, msg_type: str, msg, log_time_ns: int = 0):
        """Account one decoded message (one of another type than SEQUENCED_TYPES is ignored: None)."""
        span = sequence_span(msg_type, msg)
        if span is None:
            return None
        return self.observe(topic, span[0], span[1], log_time_ns)

    def summary(self) -> dict:
        return {'sequence_gaps': self.gaps, 'samples_lost': self.samples_lost,
                'sequence_restarts': self.restarts, 'samples_seen': self.samples_seen,
                'samples_lost_by_topic': dict(self.lost_by_topic)}
