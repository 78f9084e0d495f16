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

"""Synthetic recorder input: sample batches and status messages as the nodes publish them, as dicts."""
import numpy as np

BATCH_T = 'msg_defs/msg/RigSampleBatch'
N = 20                     # samples per batch (1 kHz rig, 50 batches/s)
DT = 1e-3


def batch(k, first=None):
    first = k * N if first is None else first
    n = np.arange(first, first + N)
    t_ns = first * 1_000_000
    return {'header': {'stamp': {'sec': t_ns // 10**9, 'nanosec': t_ns % 10**9}},
            'first_sequence': first, 'sample_period': DT,
            'displacement': 1e-3 * np.sin(0.02 * n), 'force': 2e3 * np.sin(0.02 * n + 0.3),
            'setpoint': 1e-3 * np.sin(0.02 * n + 0.01), 'temperature': 23.0 + 0.001 * k,
            'status_flags': k % 2, 'frames_lost': 0}


def stream(n_batches=300):
    """(topic, type, message, log_time_ns): batches at 50/s plus a status message every second."""
    out = []
    for k in range(n_batches):
        t = 1_700_000_000_000_000_000 + k * N * 1_000_000
        out.append(('/rig/samples', BATCH_T, batch(k), t))
        if k % 50 == 0:
            out.append(('/rig/status', 'msg_defs/msg/RigStatus', {'state': 2, 'state_name': 'running'}, t))
    return out


# -- a run with every kind of sequence event, as the recorder receives it (the loss-ledger tests) ------------------
BASE = 3_500_000           # the rig has been sampling for an hour at 1 kHz: sample numbers in the millions
SETPOINT_T = 'msg_defs/msg/SetpointBatch'
PREDICTION_T = 'msg_defs/msg/ModelPrediction'
STATUS_T = 'msg_defs/msg/RigStatus'
RUN_TOTALS = {'sequence_gaps': 3, 'samples_lost': 2 * N + 7 + 3 * N, 'sequence_jumps': 1, 'sequence_restarts': 1,
              'frames_lost': 7}


class _Run:
    """Builds the messages of a run in the order the recorder receives them, with the publication sequence of
    each publisher, and the true loss after each message (counted here by construction, not by the ledger)."""

    def __init__(self):
        self.messages = []       # (topic, type, message dict, log_time_ns, publication sequence)
        self.truth = []          # per message: the true loss counts of the sample stream after it
        self.counts = dict.fromkeys(RUN_TOTALS, 0)
        self.pending = dict.fromkeys(RUN_TOTALS, 0)   # revealed by the next sample message the recorder gets
        self.pubseq = {}         # publisher -> last publication sequence
        self.t = 1_800_000_000_000_000_000
        self.published = []      # every sample sequence the rig driver published (received or not)

    def _publish(self, publisher):
        self.pubseq[publisher] = self.pubseq.get(publisher, 0) + 1
        return self.pubseq[publisher]

    def reveal(self, **counts):
        for key, n in counts.items():
            self.pending[key] += n

    def _deliver(self, topic, msg_type, msg, pub):
        self.t += 1_000_000
        if msg_type == BATCH_T:
            for key, n in self.pending.items():
                self.counts[key] += n
            self.pending = dict.fromkeys(RUN_TOTALS, 0)
        self.messages.append((topic, msg_type, msg, self.t, pub))
        self.truth.append(dict(self.counts))

    def samples(self, publisher, first, deliver=True, frames_lost=0):
        pub = self._publish(publisher)
        self.published.extend(range(first, first + N))
        msg = dict(batch(0, first), frames_lost=frames_lost)
        if deliver:
            self._deliver('/rig/samples', BATCH_T, msg, pub)
        return first + N

    def setpoints(self, publisher, first, n=N):
        pub = self._publish(publisher)
        x = 1e-3 * np.sin(0.02 * np.arange(first, first + n))
        self._deliver('/rig/setpoints', SETPOINT_T, {
            'header': batch(0, first)['header'], 'stream_id': 1, 'source': publisher, 'first_sequence': first,
            'sample_period': DT, 'displacement': x, 'block_index': 0, 'end_of_stream': False}, pub)
        return first + n

    def prediction(self, publisher, first, deliver=True):
        pub = self._publish(publisher)
        b = batch(0, first)
        if deliver:
            self._deliver('/rig/prediction', PREDICTION_T, {
                'header': b['header'], 'first_sequence': first, 'sample_period': DT, 'displacement': b['displacement'],
                'measured_force': b['force'], 'predicted_force': 0.9 * b['force'], 'residual': 0.1 * b['force'],
                'branches': []}, pub)

    def status(self):
        self._deliver('/rig/status', STATUS_T, {'state': 2, 'state_name': 'running'}, self._publish('status'))


def loss_run():
    """(messages, truth, published) of a run that has every sequence event the loss ledger must tell apart:

    - the sample stream (/rig/samples, batches of N = 20): 2 batches (40 samples) lost in transport (their
      publication sequence skipped), 7 samples the driver lost on the bus (``frames_lost``), a jump of 700 samples
      between two programs (nothing published: not loss), and a restarted rig driver (numbering from 0 again) whose
      first 3 batches (60 samples) were published before the recorder matched it: 107 samples lost in 3 gaps, 1
      jump, 1 restart;
    - setpoints (/rig/setpoints), sample numbers of the samples they are for: a held program resumed below its
      last setpoint, a second excitation publishing its own stream, a new stream after the driver restart;
    - predictions (/rig/prediction): a batch the model skipped, a batch predicted again, the restart.
    None of the setpoint or prediction events is a lost sample. ``truth[i]``: RUN_TOTALS-like counts after
    message i; ``published``: every sample sequence the drivers published.
    """
    r = _Run()
    rig, exc, exc2, model = 'rig_driver', 'excitation', 'excitation_2', 'element_model'
    seq, sp = BASE, BASE + 200                       # setpoints run 200 samples (the lead) ahead
    sp = r.setpoints(exc, sp, 200)
    for k in range(90):                              # program 1
        if k % 30 == 0:
            r.status()
        lost = k in (40, 41)                         # published, never received (transport)
        if k == 42:
            r.reveal(samples_lost=2 * N, sequence_gaps=1)
        frames = 7 if k == 60 else 0
        if frames:                                   # the driver lost 7 frames on the bus: never published
            seq += frames
            r.reveal(samples_lost=frames, frames_lost=frames, sequence_gaps=1)
        first = seq
        seq = r.samples(rig, first, deliver=not lost, frames_lost=frames)
        if k == 70:                                  # hold; resumed below the last setpoint (same publisher)
            sp = r.setpoints(exc, seq + 20)
        elif k == 75:                                # a second excitation streams too (its own publication count)
            r.setpoints(exc2, seq - 500)
            r.setpoints(exc2, seq - 450)
        else:
            sp = r.setpoints(exc, sp)
        r.prediction(model, first, deliver=k != 50)  # batch 50: the model skipped it
        if k == 80:
            r.prediction(model, first - 10 * N)      # a batch predicted again (the model caught up late)
    seq += 700                                       # the rig idled: program 2 starts 700 samples later
    r.reveal(sequence_jumps=1)
    sp = r.setpoints(exc, seq, 200)                  # a new stream: 200 samples (the lead) at once
    for _ in range(30):                              # program 2
        first = seq
        seq = r.samples(rig, first)
        sp = r.setpoints(exc, sp)
        r.prediction(model, first)
    # the rig driver restarts: a new publisher numbering from 0; the recorder matches it at its 4th batch
    r.pubseq.pop(rig)
    seq = 0
    for _ in range(3):
        seq = r.samples(rig, seq, deliver=False)
    r.reveal(samples_lost=3 * N, sequence_gaps=1, sequence_restarts=1)
    sp = r.setpoints(exc, seq + 200, 200)
    r.status()
    for _ in range(40):                              # program 3 on the restarted rig
        first = seq
        seq = r.samples(rig, first)
        sp = r.setpoints(exc, sp)
        r.prediction(model, first)
    assert r.counts == RUN_TOTALS, r.counts
    return r.messages, r.truth, r.published
