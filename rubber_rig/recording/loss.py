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

"""How much of a run a recording holds: the file's own gaps plus every published sample that is not in it."""
from pathlib import Path

import numpy as np

from .reader import load_recording


def recording_loss(mcap: Path, published, recorder_stats: dict) -> dict:
    """Loss of the recording: what the file itself shows (sequence gaps that are real loss) plus every sample
    published during the run (``published``: the monitor's StreamStats of ``samples``) that is not in the file.
    ``samples_lost`` is the total; it is never 0 while a published sample is missing.
    """
    try:
        rec = load_recording(mcap, allow_truncated=True)
    except Exception as exc:   # the summary still says where the file is and what is known missing
        return {'error': str(exc), 'samples_lost': published.samples or 'unknown',
                'samples_not_recorded': published.samples}
    seq = np.asarray(rec.sequence, dtype=np.int64)
    if published.first is not None:
        in_run = int(np.count_nonzero((seq >= published.first) & (seq < published.next)))
    else:
        in_run = 0
    not_recorded = max(0, published.samples - in_run)
    return {'samples': int(len(rec)), 'samples_lost': int(rec.samples_lost) + not_recorded,
            'samples_lost_in_file': int(rec.samples_lost), 'samples_not_recorded': not_recorded,
            'samples_published': published.samples, 'gaps': len(rec.gaps), 'sequence_jumps': len(rec.jumps),
            'complete': bool(rec.complete), 'unclosed': rec.unclosed,
            'recorder_samples_lost': recorder_stats.get('samples_lost_total'),
            'topics': {t: v.get('count') for t, v in rec.topics.items()}}
