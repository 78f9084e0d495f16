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

"""Judging a damaged log without blaming the controller for the log's faults (``conformance --log``).

A log whose time steps back or jumps, or that lost lines, would show the controller's periodic frames late, its
feedback rate off and its sequence broken at exactly those places. The log is cut there (Trace.segments) and each
stretch is judged on its own (passive.check_offline); a requirement fails when it fails within a stretch, passes
when it passes in one and fails in none. What is wrong with the log itself is its verdict (Trace.log_verdict).
"""
from __future__ import annotations

from .passive import check_offline
from .report import Results
from .trace import Trace

MAX_SEGMENTS = 50    # more stretches than this: judged as one (too short to judge apart), the verdict says why


def check_log(trace: Trace) -> Results:
    """Every requirement a log can show, judged within the stretches between its damage (see module doc)."""
    segments = trace.segments()
    if len(segments) <= 1 or len(segments) > MAX_SEGMENTS:
        return check_offline(trace)
    results = Results()
    for frames in segments:
        part = Trace(trace.sample_rate, frames=list(frames), source=trace.source)
        for r in check_offline(part).ordered():
            results.put(r.id, r.status, r.measured, r.detail)
    return results
