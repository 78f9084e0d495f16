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
