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

"""load_recording: MCAP recordings (ours, or `ros2 bag record`'s of the same topics) -> numpy arrays.

Topics are found by message type, not by name, so namespaces do not matter:
- msg_defs/msg/RigSampleBatch (or RigSample) -> per-sample ``time`` [s since the first sample],
  ``time_ns`` (absolute), ``displacement`` [m], ``force`` [N], ``setpoint`` [m], ``temperature``
  [degC], ``status`` (status_flags), ``sequence``; a batch's temperature and status apply to all its
  samples. If several topics carry samples, the one named ``samples`` wins.
- msg_defs/msg/ModelPrediction -> ``prediction`` and ``residual`` [N], joined on the sample sequence
  (NaN where no prediction was recorded).
- msg_defs/msg/SetpointBatch -> ``block_index`` joined on the sequence (-1 where unknown).
- every other topic -> ``messages[topic]``: list of (log_time_ns, decoded message).
- metadata: the ``rubber_rig`` record (specimen, temperature, model, ...) of the first file;
  ``closing``: the loss reports (``rubber_rig.close``) of the files; ``loss``, ``samples_lost``, ``gaps``:
  the loss ledger (gaps.LossLedger: the same one the recorder and ``recover`` keep) of the sample stream, computed
  from the data itself in file order (so it is known for foreign recordings too): bus loss the driver reported
  (``frames_lost``) and messages missed in transport (the stored DDS publication sequence skipped); a
  sequence jump with nothing published in between (between two programs) is not a loss (``jumps``).
- ``parts``: the parts of a split recording (parts.survey, from the directory or any one part): which are
  missing and how many samples they held; a recording with a missing part is not ``complete``.
- a file that was not closed (recorder killed, write error) is read up to its last complete chunk when
  ``allow_truncated``; ``unclosed`` says where its intact data ends, and ``tail_unaccounted`` that an
  unknown number of samples after that point is missing (``loss_text()`` says it in words).
"""
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import RecordingError
from .gaps import BATCH, SAMPLE, SAMPLE_TYPES, LossLedger, sample_topic
from .mcapio import Decoders, read_file, recording_files
from .metadata import (
    BOOKKEEPING_TOPIC,
    CLOSE_METADATA_NAME,
    METADATA_NAME,
    SEQUENCE_SOURCE_KEY,
    bookkeeping_records,
    decode_metadata,
)
from .parts import PartsReport, survey

PREDICTION = 'msg_defs/msg/ModelPrediction'
SETPOINTS = 'msg_defs/msg/SetpointBatch'
SIGNALS = ('time', 'displacement', 'force', 'setpoint', 'prediction', 'residual', 'temperature',
           'status', 'sequence', 'block_index')


@dataclass
class Recording:
    files: list
    metadata: dict = field(default_factory=dict)
    closing: list = field(default_factory=list)
    topics: dict = field(default_factory=dict)      # topic -> {'type', 'count', 'qos'}
    messages: dict = field(default_factory=dict)    # other topics: topic -> [(log_time_ns, msg)]
    other_metadata: dict = field(default_factory=dict)
    loss: dict = field(default_factory=dict)        # the loss ledger's counts (gaps.LossLedger.summary)
    gaps: list = field(default_factory=list)        # the first gap events (gaps.MAX_EVENTS); the count is in loss
    samples_lost: int = 0
    jumps: list = field(default_factory=list)       # sequence jumps that are not loss (between programs)
    complete: bool = True
    unclosed: list = field(default_factory=list)    # per unclosed file: where its intact data ends
    parts: PartsReport = None                       # the parts of the recording (parts.survey; None for a list)
    start_ns: int = 0
    end_ns: int = 0
    sample_period: float = float('nan')
    time_ns: np.ndarray = None
    time: np.ndarray = None
    displacement: np.ndarray = None
    force: np.ndarray = None
    setpoint: np.ndarray = None
    temperature: np.ndarray = None
    status: np.ndarray = None
    sequence: np.ndarray = None
    prediction: np.ndarray = None
    residual: np.ndarray = None
    block_index: np.ndarray = None

    @property
    def duration(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9

    @property
    def signals(self) -> dict:
        return {name: getattr(self, name) for name in SIGNALS}

    def __len__(self):
        return len(self.sequence)

    @property
    def sequence_gaps(self) -> int:
        """Sequence gaps that are loss, all of them (``gaps`` lists the first gaps.MAX_EVENTS)."""
        return int(self.loss.get('sequence_gaps', len(self.gaps)))

    @property
    def tail_unaccounted(self) -> bool:
        """True if a file was not closed: samples after its last intact chunk are missing, how many is
        unknown (the recorder that knew was killed or could not write).
        """
        return bool(self.unclosed)

    def loss_text(self) -> str:
        """The loss of this recording in words (one line per finding), never '0 lost' when unknown."""
        lines = []
        known = f'{self.samples_lost} samples lost in {self.sequence_gaps} sequence gaps'
        jumps = self.loss.get('sequence_jumps', len(self.jumps))
        if jumps:
            known += f' ({jumps} sequence jumps between programs, not loss)'
        if self.unclosed:
            lines.append(known + ' within the intact data, plus an unknown number after its end:')
            for u in self.unclosed:
                seq = '' if u['last_sequence'] is None else f", last sample sequence {u['last_sequence']}"
                lines.append(f"  {u['file']}: NOT CLOSED (recorder killed or its writes failed); intact data ends "
                             f"at log time {u['last_log_time_ns'] / 1e9:.3f} s{seq}; samples after that are "
                             f'unaccounted for')
        else:
            lines.append(known)
        if self.parts is not None and not self.parts.complete:
            lines += self.parts.lines()
        return '\n'.join(lines)


def load_recording(path, *, allow_truncated: bool = False) -> Recording:
    """Load a recording (file, directory of split files, or list of files) into arrays.

    A truncated file (writer killed) raises RecordingError suggesting ``rubber-rig recover``, unless
    ``allow_truncated`` (then everything up to the last complete chunk is read). A corrupt file raises
    RecordingError naming the damaged record and its offset.
    """
    files = recording_files(path)
    rec = Recording(files=[str(f) for f in files])
    raw = []                    # in file order: (file index, log_time, topic, type, schema, data, file, pub. sequence)
    for i, f in enumerate(files):
        schemas, channels, messages, metadata, complete = read_file(Path(f), allow_truncated)
        rec.complete &= complete
        if not complete:
            rec.unclosed.append({'file': str(f), 'last_log_time_ns': max((m[1] for m in messages), default=0),
                                 'last_sequence': None, 'messages': len(messages)})
        for name, values in metadata:
            if name == METADATA_NAME:
                if not rec.metadata:
                    rec.metadata = decode_metadata(values)
            elif name == CLOSE_METADATA_NAME:
                rec.closing.append(decode_metadata(values))
            else:
                rec.other_metadata.setdefault(name, values)
        for channel_id, log_time, _, sequence, data in messages:
            channel = channels.get(channel_id)
            if channel is None:
                raise RecordingError(f'{f}: message on unknown channel {channel_id}')
            schema = schemas.get(channel.schema_id)
            if schema is None:
                raise RecordingError(f'{f}: topic {channel.topic} has no schema')
            if channel.message_encoding != 'cdr':
                raise RecordingError(f'{f}: topic {channel.topic} is encoded as '
                                     f'{channel.message_encoding!r}; only cdr is supported')
            info = rec.topics.setdefault(channel.topic, {
                'type': schema.name, 'count': 0,
                'qos': channel.metadata.get('offered_qos_profiles', '')})
            info['count'] += 1
            pubseq = sequence if channel.metadata.get(SEQUENCE_SOURCE_KEY) == 'publication' else None
            raw.append((i, log_time, channel.topic, schema.name, schema, data, f, pubseq))
    if raw:
        rec.start_ns = min(r[1] for r in raw)
        rec.end_ns = max(r[1] for r in raw)
    types = {topic: info['type'] for topic, info in rec.topics.items()}
    samples_from = sample_topic(types)
    pred_topic = _pick(types, PREDICTION, 'prediction')
    setp_topic = _pick(types, SETPOINTS, 'setpoints')
    decoders = {f: Decoders(f) for f in files}
    # the loss ledger sees the sample messages in the order they were written, as the recorder did
    ledger, decoded = LossLedger(), {}
    for k, (_, log_time, topic, type_name, schema, data, f, pubseq) in enumerate(raw):
        if type_name in SAMPLE_TYPES:
            msg = decoded[k] = decoders[f].decode(schema, data, topic)
            ledger.observe(topic, type_name, msg, log_time, pubseq)
    samples, predictions, setpoints = [], [], []
    # the arrays and message lists are in log-time order within each file (stable: file order among equal times)
    for k in sorted(range(len(raw)), key=lambda k: (raw[k][0], raw[k][1])):
        _, log_time, topic, type_name, schema, data, f, pubseq = raw[k]
        dec = decoders[f]
        if topic == samples_from:
            samples.append((decoded[k], str(f)))
        elif topic == pred_topic:
            predictions.append(dec.decode(schema, data, topic))
        elif topic == setp_topic:
            setpoints.append(dec.decode(schema, data, topic))
        elif type_name not in (BATCH, SAMPLE, PREDICTION, SETPOINTS):
            rec.messages.setdefault(topic, []).append((log_time, dec.decode(schema, data, topic)))
    _fill_samples(rec, samples, samples_from)
    rec.loss = ledger.summary()
    rec.samples_lost = ledger.samples_lost
    rec.gaps = [e for e in ledger.events if e['kind'] == 'gap']
    rec.jumps = [e for e in ledger.events if e['kind'] == 'jump']
    _join(rec, predictions, setpoints)
    _metadata_from_topics(rec)
    if not isinstance(path, (list, tuple)):
        _survey_parts(rec, path)
    return rec


def _survey_parts(rec: Recording, path) -> None:
    """The parts of the recording ``path`` belongs to (parts.survey): a missing part makes it incomplete."""
    try:
        rec.parts = survey(path)
    except (OSError, RecordingError) as exc:   # the data is read; only the part records could not be
        rec.other_metadata['parts_error'] = {'error': str(exc)}
    else:
        rec.complete &= rec.parts.complete


def _pick(types: dict, msg_type: str, preferred: str):
    """The topic of ``msg_type`` named ``preferred`` (last name part), else the first of that type by name."""
    topics = sorted(t for t, ty in types.items() if ty == msg_type)
    for topic in topics:
        if topic.rstrip('/').split('/')[-1] == preferred:
            return topic
    return topics[0] if topics else None


def _metadata_from_topics(rec: Recording):
    """Fill what the metadata record lacks (e.g. `ros2 bag record` files) from latched topics: the
    program YAML (std_msgs/String on ``program``), the rig's configuration with the load cell's declared
    calibration (``rig_configuration``) and the model parameters (ModelParameters); and, for a file
    whose MCAP metadata records were lost in a conversion (rosbags: MCAP -> sqlite3 -> MCAP), the records from
    the bookkeeping messages the writer adds (``<namespace>/recording_info``, one per closed file).
    """
    for topic, msgs in rec.messages.items():
        if rec.topics[topic]['type'] != 'std_msgs/msg/String' or not topic.endswith('/' + BOOKKEEPING_TOPIC):
            continue
        records = [r for r in (bookkeeping_records(m.data) for _, m in msgs) if r]
        if records and not rec.metadata and METADATA_NAME in records[0]:
            rec.metadata = dict(records[0][METADATA_NAME])
        if records and not rec.closing:
            rec.closing = [dict(r[CLOSE_METADATA_NAME]) for r in records if CLOSE_METADATA_NAME in r]
    for topic, msgs in rec.messages.items():
        info = rec.topics[topic]
        last = msgs[-1][1] if msgs else None
        if last is None:
            continue
        name = topic.rstrip('/').split('/')[-1]
        if info['type'] == 'std_msgs/msg/String' and name == 'program':
            rec.metadata.setdefault('test_program', last.data)
        elif info['type'] == 'std_msgs/msg/String' and name == 'rig_configuration':
            rec.metadata.setdefault('rig_configuration', last.data)   # the driver's, with the load-cell calibration
        elif info['type'] == 'msg_defs/msg/ModelParameters':
            rec.metadata.setdefault('model', last.model_name)
            rec.metadata.setdefault('parameter_set', last.parameter_set)
            rec.metadata.setdefault('model_temperature', float(last.temperature))
            rec.metadata.setdefault('model_parameters', dict(zip(last.names, map(float, last.values), strict=False)))


def _stamp_ns(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _cat(parts, dtype):
    return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype)


def _fill_samples(rec: Recording, samples, topic):
    t, d, fo, sp, te, st, seq = [], [], [], [], [], [], []
    periods = []
    last_in_file = {}
    for m, f in samples:
        if hasattr(m, 'first_sequence'):                       # RigSampleBatch
            n = len(m.displacement)
            first = int(m.first_sequence)
            period = float(m.sample_period)
            periods.append(period)
            t.append(_stamp_ns(m) + np.round(np.arange(n) * period * 1e9).astype(np.int64))
            d.append(np.asarray(m.displacement, dtype=float))
            fo.append(np.asarray(m.force, dtype=float))
            sp.append(np.asarray(m.setpoint, dtype=float))
            te.append(np.full(n, float(m.temperature)))
            st.append(np.full(n, int(m.status_flags), dtype=np.uint32))
            seq.append(np.arange(first, first + n, dtype=np.uint64))
        else:                                                  # RigSample
            n, first = 1, int(m.sequence)
            t.append(np.array([_stamp_ns(m)], dtype=np.int64))
            d.append(np.array([m.displacement]))
            fo.append(np.array([m.force]))
            sp.append(np.array([m.setpoint]))
            te.append(np.array([m.temperature]))
            st.append(np.array([m.status_flags], dtype=np.uint32))
            seq.append(np.array([first], dtype=np.uint64))
        if len(fo[-1]) != n or len(sp[-1]) != n:
            raise RecordingError(f'{topic}: batch at sequence {first} has arrays of different '
                                 f'lengths ({n}, {len(fo[-1])}, {len(sp[-1])})')
        if n:
            last_in_file[f] = first + n - 1
    rec.time_ns = _cat(t, np.int64)
    rec.time = (rec.time_ns - rec.time_ns[0]) * 1e-9 if len(rec.time_ns) else np.zeros(0)
    rec.displacement, rec.force, rec.setpoint = _cat(d, float), _cat(fo, float), _cat(sp, float)
    rec.temperature, rec.status, rec.sequence = _cat(te, float), _cat(st, np.uint32), _cat(seq, np.uint64)
    for u in rec.unclosed:
        u['last_sequence'] = last_in_file.get(u['file'])
    if periods:
        rec.sample_period = float(np.median(periods))


def _lookup(rec_seq, seq, values, fill):
    """Values at rec_seq positions, joined on sequence numbers (``seq`` -> ``values``)."""
    out = np.full(len(rec_seq), fill, dtype=np.asarray(values).dtype if len(values) else float)
    if not len(seq) or not len(rec_seq):
        return out
    order = np.argsort(seq, kind='stable')
    seq, values = seq[order], np.asarray(values)[order]
    idx = np.clip(np.searchsorted(seq, rec_seq), 0, len(seq) - 1)
    hit = seq[idx] == rec_seq
    out[hit] = values[idx[hit]]
    return out


def _join(rec: Recording, predictions, setpoints):
    pseq, pforce, presid = [], [], []
    for m in predictions:
        n, first = len(m.predicted_force), int(m.first_sequence)
        pseq.append(np.arange(first, first + n, dtype=np.uint64))
        pforce.append(np.asarray(m.predicted_force, dtype=float))
        resid = np.asarray(m.residual, dtype=float)
        presid.append(resid if len(resid) == n else np.full(n, np.nan))
    seq = _cat(pseq, np.uint64)
    rec.prediction = _lookup(rec.sequence, seq, _cat(pforce, float), np.nan)
    rec.residual = _lookup(rec.sequence, seq, _cat(presid, float), np.nan)
    sseq, blocks = [], []
    for m in setpoints:
        n, first = len(m.displacement), int(m.first_sequence)
        sseq.append(np.arange(first, first + n, dtype=np.uint64))
        blocks.append(np.full(n, int(m.block_index), dtype=np.int32))
    rec.block_index = _lookup(rec.sequence, _cat(sseq, np.uint64), _cat(blocks, np.int32), -1)
    if rec.block_index.dtype != np.int32:
        rec.block_index = rec.block_index.astype(np.int32)
