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

"""How much of a run a recording holds: the file's own loss (the loss ledger, as ``rubber-rig info``, ``recover``
and the recorder count it) plus the published samples the file neither holds nor counts as lost.
"""
from pathlib import Path

import numpy as np

from .reader import load_recording


def recording_loss(mcap: Path, published, recorder_stats: dict) -> dict:
    """Loss of the recording: the file's ledger (``samples_lost_in_file``, ``gaps``: what ``rubber-rig info``
    shows for it) plus ``samples_not_recorded``: samples published during the run (``published``: the monitor's
    StreamStats of ``samples``: ``first``, ``next``, ``samples``) before the first or after the last sample of the
    run the file holds. A published sample between those two is in the file or in one of its gaps, which the
    ledger counts already (a transport loss is one gap, not a gap plus a sample not recorded). ``samples_lost``
    is the total; it is never 0 while a published sample is missing.
    """
    try:
        rec = load_recording(mcap, allow_truncated=True)
    except Exception as exc:   # the summary still says where the file is and what is known missing
        return {'error': str(exc), 'samples_lost': published.samples or 'unknown',
                'samples_not_recorded': published.samples}
    seq = np.asarray(rec.sequence, dtype=np.int64)
    if published.first is not None:
        run = seq[(seq >= published.first) & (seq < published.next)]
    else:
        run = seq[:0]
    missing = max(0, published.samples - len(run))       # published, not in the file (inside its gaps or not)
    if len(run):
        outside = int(run.min() - published.first) + int(published.next - 1 - run.max())
        not_recorded = min(missing, outside)
    else:
        not_recorded = missing
    return {'samples': int(len(rec)), 'samples_lost': int(rec.samples_lost) + not_recorded,
            'samples_lost_in_file': int(rec.samples_lost), 'samples_not_recorded': not_recorded,
            'samples_published': published.samples, 'gaps': rec.sequence_gaps,
            'sequence_jumps': int(rec.loss.get('sequence_jumps', len(rec.jumps))),
            'complete': bool(rec.complete), 'unclosed': rec.unclosed,
            'recorder_samples_lost': recorder_stats.get('samples_lost_total'),
            'topics': {t: v.get('count') for t, v in rec.topics.items()}}
