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

"""Berg's reversal deadband as a schedule: which reversals a displacement makes, whatever the friction parameters.

The deadband rule of `rubber_rig.models.friction` (a reversal is accepted once the displacement has moved more
than d back from the extreme reached since the last one) decides on the displacement and d alone; f_fmax and x2
only set the forces. A fit runs Berg's element hundreds of times over one measured displacement with other
parameters, so the decisions (:func:`deadband_schedule`) are made once and kept (:func:`cached_schedule`), and
each run is Eq. 16 evaluated in one vectorised pass (``BergFriction._run_deadband``).
"""
from __future__ import annotations

import hashlib
from collections import OrderedDict
from typing import NamedTuple

import numpy as np

# batch: after a stretch between accepted reversals shorter than _DENSE/2 samples, the next one runs sample by
# sample (cheaper than numpy calls on a few samples)
_DENSE = 96


class DeadbandSchedule(NamedTuple):
    """What the reversal deadband makes of a displacement, whatever the friction parameters (one call's worth).

    segment: (n,) int, the branch each sample is on (0 = the one in progress when the call starts, k = after the
    k-th reversal accepted in the call); candidate: indices of the samples back inside the band, which follow
    Eq. 16 from the candidate reference (extreme, F(extreme)); extreme: (len(candidate),) that extreme [m];
    refs: the accepted extremes [m], reference of branches 1, 2, ...; direction, x_ext: the state at the end.
    """

    segment: np.ndarray
    candidate: np.ndarray
    extreme: np.ndarray
    refs: list
    direction: int
    x_ext: float


def deadband_schedule(x: np.ndarray, thr: float, direction: int, x_ext: float, x_s: float) -> DeadbandSchedule:
    """The accepted reversals and each sample's reference under the deadband ``thr`` [m] (module docstring),
    from the state (direction, x_ext, x_s) at the start of ``x`` [m], shape (n,): ``_step_deadband``'s decisions
    without its forces. Between accepted reversals the extreme is a running max (min) over a window sized from
    the previous stretch (doubled until the next reversal shows up); stretches shorter than a few samples (noise
    larger than d) are cheaper sample by sample.
    """
    n = x.size
    segment = np.zeros(n, np.int32)
    inside = np.zeros(n, bool)
    extreme = np.zeros(n)
    refs = []
    s, xe = int(direction), float(x_ext)
    i, start, width = 0, 0, 64      # next sample, first sample of the current stretch, window length
    while i < n:
        if s == 0 or width <= _DENSE:
            s0 = s
            for v in x[i:i + _DENSE].tolist():
                segment[i] = len(refs)
                if s == 0:                      # virgin: the branch from (x_s, F_fs) both ways until |x - x_s| > d
                    if abs(v - x_s) > thr:
                        s, xe = (1 if v > x_s else -1), v
                elif s * v >= s * xe:           # at or beyond the extreme
                    xe = v
                elif s * xe - s * v <= thr:     # back inside the band
                    inside[i], extreme[i] = True, xe
                else:                           # more than d back: accepted at the extreme
                    refs.append(xe)
                    segment[i] = len(refs)
                    s, xe = -s, v
                i += 1
                if s != s0:                     # this sample started a new stretch
                    width, start = 2 * (i - start), i - 1
                    break
            else:
                width = 4 * _DENSE
            continue
        w = x[i:i + width]
        sw = s * w                                          # exact sign flip: work as if rising
        m = np.maximum.accumulate(np.maximum(sw, s * xe))   # extreme so far (in s-space)
        back = m - sw > thr
        k = int(back.argmax()) if back.any() else w.size   # first sample more than d back
        if k:
            segment[i:i + k] = len(refs)
            inside[i:i + k] = sw[:k] < m[:k]
            extreme[i:i + k] = s * m[:k]
            xe = float(s * m[k - 1])
        i += k
        if k == w.size:
            width *= 2
            continue
        refs.append(xe)                                     # accepted at the extreme; sample i starts the branch
        segment[i] = len(refs)
        s, xe = -s, float(x[i])
        width, start = 2 * (i - start), i
        i += 1
    candidate = np.flatnonzero(inside).astype(np.int32)
    return DeadbandSchedule(segment, candidate, extreme[candidate], refs, s, xe)


_SCHEDULES: OrderedDict = OrderedDict()
_SCHEDULE_CACHE = 32         # schedules kept (a fit's recordings in ParallelModel chunks: 4 per 100 s at 1 kHz)
_SCHEDULE_MIN = 1024         # shorter calls (streaming) are not worth a key


def cached_schedule(x: np.ndarray, thr: float, direction: int, x_ext: float, x_s: float) -> DeadbandSchedule:
    """:func:`deadband_schedule`, kept for the last ``_SCHEDULE_CACHE`` displacements seen (keyed by a digest of
    their bytes and the starting state), so that a fit's hundreds of runs over one measured displacement find
    the reversals once.
    """
    if x.size < _SCHEDULE_MIN:
        return deadband_schedule(x, thr, direction, x_ext, x_s)
    digest = hashlib.blake2b(np.ascontiguousarray(x).view(np.uint8), digest_size=16).digest()
    key = (digest, x.size, thr, int(direction), x_ext, x_s if direction == 0 else None)
    found = _SCHEDULES.get(key)
    if found is None:
        found = _SCHEDULES[key] = deadband_schedule(x, thr, direction, x_ext, x_s)
        if len(_SCHEDULES) > _SCHEDULE_CACHE:
            _SCHEDULES.popitem(last=False)
    else:
        _SCHEDULES.move_to_end(key)
    return found
