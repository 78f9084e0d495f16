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

"""The gap check of a file being written: sample-stream messages are decoded as they are written and fed to
the loss ledger (gaps.LossLedger, the one that load_recording and recover use too), and their samples counted,
so that the file's close record says what was lost, in the numbers ``rubber-rig info`` shows for the file.

This is accounting, not I/O, so it lives apart from the writer. The ledger may carry on from the earlier
files of a split recording: :meth:`GapCheck.report` covers what this file added, plus the totals so far.
"""
from .gaps import SAMPLE_TYPES, LossLedger, sequence_span
from .mcapio import Decoders


class GapCheck:
    """Sequence gaps and sample counts of the messages written to one file."""

    def __init__(self, path, gaps: LossLedger = None):
        # numpy decoder for the gap check (10 kHz), mcap_ros2's only if it fails (e.g. big-endian CDR)
        self._decoders = Decoders(path, lazy_fallback=True)
        self.gaps = gaps if gaps is not None else LossLedger()
        self._counts_at_open = self.gaps.counts()
        self._events_at_open = {topic: len(t.events) for topic, t in self.gaps.trackers.items()}
        self.samples_written = 0           # samples of sample-stream messages (RigSampleBatch, ...) written
        self.samples_flushed = 0           # ... of them in complete chunks handed to the OS
        self.samples_lost_unwritten = 0    # samples of the chunk a write error lost
        self._spans = {}                   # sample topic -> [samples, first sequence, last sequence] in this file

    def observe(self, topic, msg_type, schema, data, decoded, log_time_ns, publication_sequence=None) -> bool:
        """Check one written message (``decoded``, or its CDR ``data`` under ``schema``); False if its bytes
        could not be decoded (they are recorded anyway: the writer counts them). ``publication_sequence``: the
        sequence stored for it if its channel stores publication sequence numbers, else None (as readers see it).
        """
        if msg_type not in SAMPLE_TYPES:
            return True
        if decoded is None:
            try:
                decoded = self._decoders.decode(schema, data, topic)
            except Exception:  # the decoders raise many types on bad bytes; the caller counts them
                return False
        self.gaps.observe(topic, msg_type, decoded, log_time_ns, publication_sequence)
        span = sequence_span(msg_type, decoded)
        if span is not None:
            self.samples_written += span[1]
            if span[1]:
                held = self._spans.setdefault(topic, [0, span[0], span[0]])
                held[0] += span[1]
                held[2] = span[0] + span[1] - 1
        return True

    def part(self) -> dict:
        """What this file holds of the recording's sample stream (the ledger's topic): ``part_samples`` (its
        samples), ``first_sample`` and ``last_sample`` (sequence numbers of the first and last, in file order;
        None if it holds none): the part's place in a split recording (see parts).
        """
        samples, first, last = self._spans.get(self.gaps.topic, (0, None, None))
        return {'part_samples': samples, 'first_sample': first, 'last_sample': last}

    def flushed(self) -> None:
        """Every sample written so far is in a complete chunk on disk."""
        self.samples_flushed = self.samples_written

    def chunk_lost(self) -> None:
        """A write error lost the chunk in progress, and the samples in it."""
        self.samples_lost_unwritten = self.samples_written - self.samples_flushed

    def report(self) -> dict:
        """The gap part of the writer's loss report (sequence jumps, between programs, are not loss)."""
        ledger = self.gaps
        total = ledger.summary()
        return {**ledger.summary(since=self._counts_at_open),
                'samples_lost_unwritten': self.samples_lost_unwritten,
                'gap_events': ledger.events[self._events_at_open.get(ledger.topic, 0):],
                'total_sequence_gaps': total['sequence_gaps'],
                'total_samples_lost': total['samples_lost']}
