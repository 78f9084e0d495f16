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

"""What the suite judged while the recording was made: the element model's per-cycle metrics (CycleMetrics) and
the detector events (DetectorEvent), read from a recording and placed on its sample index.

The report draws K_dyn(cycle) with the events as markers from these; both are optional (a recording of
``ros2 bag record`` without those topics has none).
"""
from __future__ import annotations

import re

import numpy as np

CYCLE_METRICS = 'msg_defs/msg/CycleMetrics'
DETECTOR_EVENT = 'msg_defs/msg/DetectorEvent'
EVENT_FIELDS = ('program', 'detector', 'kind', 'block_index', 'block_name', 'cycle', 'program_cycle', 'elapsed',
                'sequence', 'value', 'reference', 'threshold', 'units', 'action', 'cause', 'code', 'message')
_CAUSE_LABEL = re.compile(r'^\[cause ([a-z_]+)(?:/([a-z_]+))?\] ')


def _of_type(rec, type_name: str) -> list:
    """Decoded messages of every topic of `type_name`, in log-time order."""
    out = []
    for topic, info in rec.topics.items():
        if info.get('type') == type_name:
            out += rec.messages.get(topic, [])
    return [m for _, m in sorted(out, key=lambda tm: tm[0])]


def _sample_index(sequence: np.ndarray | None, seq) -> np.ndarray:
    """Sample index (into the recording's arrays) of rig sequence numbers `seq`; -1 where not recorded."""
    seq = np.asarray(seq, dtype=np.int64)
    if sequence is None or not len(sequence):
        return np.full(seq.shape, -1)
    s = np.asarray(sequence, dtype=np.int64)
    i = np.clip(np.searchsorted(s, seq), 0, s.size - 1)
    return np.where(np.abs(s[i] - seq) <= 1, i, -1)


def recorded_cycles(rec) -> dict | None:
    """The recorded per-cycle metrics as arrays ({'end_sample', 'end_sequence', 'block', 'frequency', 'amplitude',
    'k_dyn', 'k_dyn_model', 'c_eq', 'c_eq_model', 'residual_rms'}, SI), or None when none were recorded.
    """
    msgs = _of_type(rec, CYCLE_METRICS)
    if not msgs:
        return None

    def col(get):
        return np.array([float(get(m)) for m in msgs])
    out = {'end_sequence': np.array([int(m.end_sequence) for m in msgs], dtype=np.int64),
           'block': np.array([int(m.block_index) for m in msgs]),
           'frequency': col(lambda m: m.frequency), 'amplitude': col(lambda m: m.amplitude),
           'k_dyn': col(lambda m: m.measured.k_dyn), 'k_dyn_model': col(lambda m: m.model.k_dyn),
           'c_eq': col(lambda m: m.measured.c_eq), 'c_eq_model': col(lambda m: m.model.c_eq),
           'residual_rms': col(lambda m: m.residual_rms)}
    out['end_sample'] = _sample_index(rec.sequence, out['end_sequence'] - 1)
    return out


def recorded_events(rec) -> list[dict]:
    """The recorded detector events ({EVENT_FIELDS..., 'sample': index of the sample it belongs to or -1})."""
    events = []
    for m in _of_type(rec, DETECTOR_EVENT):
        e = {k: getattr(m, k, '') for k in EVENT_FIELDS}
        label = _CAUSE_LABEL.match(str(e['message'])) if not e['cause'] else None
        if label:   # recorded before DetectorEvent had the fields: the message's label carries them
            e['cause'], e['code'] = label.group(1), label.group(2) or ''
        e['sample'] = int(_sample_index(rec.sequence, [max(int(e['sequence']) - 1, 0)])[0])
        events.append(e)
    return events
