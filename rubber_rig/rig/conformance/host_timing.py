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

"""This host's own lateness during a conformance run, so that a timing verdict never blames the controller for
the host (docs/protocol.md, "Host timing").

The run measures itself: its receive loop, which should come round every few ms, and its heartbeat sender, whose
frames are due every 50 ms, record each time they ran later than due by more than LATE_MIN. A stretch of the bus
trace that overlaps such a window (widened by MARGIN) cannot show who was late: the host that did not read the
bus, or the controller. A timing requirement whose only violations fall in such stretches is *not judged*,
"this host was late by X ms", never failed; one violated elsewhere still fails. With the simulator on this host
(`--sim`) the simulator's own missed deadlines are this host's lateness too and are merged in (`add_from_file`).

All times are wall-clock seconds (time.time()), the time base of the trace.
"""
from __future__ import annotations

import threading
from pathlib import Path

import numpy as np

LATE_MIN = 0.010     # [s] a wake-up this much later than due is recorded
MARGIN = 0.005       # [s] a window is widened by this much on each side when a stretch of the trace is judged
JOIN_GAP = 0.001     # [s] windows this close are one stretch of lateness (longest_late)
SIM_LATE_MIN = 0.002  # [s] the simulator on this host logs each deadline it missed by this much (the 2 ms a
#                      controller's feedback may jitter, CTRL-FB-2): python -m rubber_rig.rig.sim --timing-log


class HostTiming:
    """Windows (start, end) [s] during which this host ran late; thread-safe to record. Each window is counted
    under the source that recorded it (sources: name -> [windows, seconds in all]) for the report.
    """

    def __init__(self):
        self.windows = []
        self.sources = {}
        self._lock = threading.Lock()
        self._read = {}          # path -> bytes of it already merged

    def due(self, t_due: float, t_now: float, source: str = 'receive loop and heartbeat') -> None:
        """Something due at t_due ran at t_now: a window when it was LATE_MIN or more late."""
        if t_now - t_due >= LATE_MIN:
            self.add(t_due, t_now, source)

    def add(self, t0: float, t1: float, source: str = 'reference controller') -> None:
        """A window [t0, t1] a part of this host recorded at its own threshold (the in-process reference
        controller's late ticks, the kernel's run-queue waits of the simulator).
        """
        with self._lock:
            self.windows.append((float(t0), float(t1)))
            count = self.sources.setdefault(source, [0, 0.0])
            count[0] += 1
            count[1] += float(t1) - float(t0)

    def add_from_file(self, path, source: str = 'simulator') -> int:
        """Merge the windows written one per line as 'start end' (the simulator's missed deadlines, at its own
        threshold: it misses the feedback timing by less than LATE_MIN) since the last call for this path; returns
        how many. A missing file adds nothing; a line still being written waits.
        """
        p = Path(path)
        if not p.is_file():
            return 0
        offset = self._read.get(str(p), 0)
        with p.open('rb') as f:
            f.seek(offset)
            data = f.read()
        complete = data[:data.rfind(b'\n') + 1]
        self._read[str(p)] = offset + len(complete)
        added = 0
        for line in complete.decode('utf-8', errors='replace').splitlines():
            parts = line.split()
            try:
                t0, t1 = float(parts[0]), float(parts[1])
            except (IndexError, ValueError):
                continue
            self.add(t0, t1, source)          # the writer chose its own threshold
            added += 1
        return added


class DropWatch:
    """Windows from successive readings of a count of frames this host lost (a socket's drops: can.udp_socket):
    update(now [s], count) returns (previous reading's time, now) when the count grew since, else None - the
    frames were lost in between, wherever the process reading them was.
    """

    def __init__(self):
        self._last = None          # (time [s], count) of the previous reading

    def update(self, now: float, count):
        if count is None:
            return None
        last, self._last = self._last, (float(now), int(count))
        if last is None or count <= last[1]:
            return None
        return (last[0], float(now))


def late_between(windows, t0: float, t1: float) -> float:
    """The longest lateness [s] of a window (start, end) that overlaps [t0, t1] widened by MARGIN, 0 if none."""
    worst = 0.0
    for a, b in windows:
        if a - MARGIN <= t1 and b + MARGIN >= t0:
            worst = max(worst, b - a)
    return worst


def late_total(windows, t0: float, t1: float) -> float:
    """How long [s] this host was late within [t0, t1] widened by MARGIN on each side: the union of the windows'
    overlaps with it. A violation longer than this cannot be the host's alone.
    """
    lo, hi = t0 - MARGIN, t1 + MARGIN
    spans = sorted((max(a, lo), min(b, hi)) for a, b in windows if a <= hi and b >= lo)
    total, end = 0.0, -float('inf')
    for a, b in spans:
        if b > end:
            total += b - max(a, end)
            end = b
    return total


def longest_late(windows, t0: float, t1: float, join: float = JOIN_GAP) -> float:
    """The longest stretch [s] this host was late without a break, among the windows that overlap [t0, t1]
    widened by MARGIN: windows of any source that overlap, or follow each other within `join` [s], are one
    stretch (the same delay seen by several sources, or a task held back sample after sample). Unlike late_total,
    many short delays spread over a long stretch do not add up: a view of the controller, or a reaction, is
    only as stale as the longest single delay.
    """
    lo, hi = t0 - MARGIN, t1 + MARGIN
    spans = sorted((a, b) for a, b in windows if a <= hi and b >= lo)
    longest, start, end = 0.0, None, -float('inf')
    for a, b in spans:
        if start is None or a > end + join:
            start, end = a, b
        else:
            end = max(end, b)
        longest = max(longest, end - start)
    return longest


class LateSpans:
    """The union of lateness windows [(start, end) s], each widened by `widen` [s] on both sides, as disjoint
    sorted spans: many stretches are then queried at once in O(log m) each (a run on a loaded host records over
    ten thousand windows, and a periodic frame's check asks for every one of ten thousand intervals).
    """

    def __init__(self, windows, widen: float = 0.0):
        starts, ends = [], []
        for a, b in sorted(windows):
            a, b = a - widen, b + widen
            if ends and a <= ends[-1]:
                ends[-1] = max(ends[-1], b)
            else:
                starts.append(a)
                ends.append(b)
        self.starts, self.ends = np.array(starts, dtype=float), np.array(ends, dtype=float)
        self._before = np.concatenate(([0.0], np.cumsum(self.ends - self.starts)))   # covered before span k

    def _covered_until(self, x):
        """How long [s] the spans cover up to x (array)."""
        j = np.searchsorted(self.starts, x, side='right') - 1
        k = np.maximum(j, 0)
        if not self.starts.size:
            return np.zeros_like(x)
        inside = np.minimum(x, self.ends[k]) - self.starts[k]
        return np.where(j >= 0, self._before[k] + inside, 0.0)

    def total(self, lo, hi):
        """How long [s] the spans cover within each [lo, hi] (arrays of one shape): late_total, all at once."""
        lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        return np.maximum(self._covered_until(hi) - self._covered_until(lo), 0.0)

    def covers(self, t):
        """Whether each time t [s] (array) lies within a span (ends included)."""
        t = np.asarray(t, dtype=float)
        if not self.starts.size:
            return np.zeros(t.shape, dtype=bool)
        j = np.searchsorted(self.starts, t, side='right') - 1
        return (j >= 0) & (t <= self.ends[np.maximum(j, 0)])


def own_intervals(windows, t, period: float):
    """The intervals between frames at times t [s] (shape (n,)) less this host's lateness around each, as far as it
    can explain them: only the part of an interval beyond `period` [s] can be the host's (a late host delays a
    frame; it never makes an on-time interval shorter). Returns (own, credited, late), each shape (n - 1,) [s]:
    what the controller alone is answerable for, the lateness credited to the host, and all of the host's
    lateness around each interval (late_total; 0 where it was on time).
    """
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    late = LateSpans(windows).total(t[:-1] - MARGIN, t[1:] + MARGIN) if t.size else dt
    credited = np.minimum(late, np.maximum(dt - period, 0.0)) if dt.size else dt
    return dt - credited, credited, late


def explains(windows, t0: float, t1: float, excess: float) -> float:
    """The host's lateness [s] within [t0, t1] when it is at least `excess` [s] (the part of a violation beyond
    its bound), else 0: only then may the violation be the host's.
    """
    late = late_total(windows, t0, t1)
    return late if late > 0 and late >= excess else 0.0


def not_judged(late: float, what: str) -> str:
    """The reason of a timing verdict that cannot be given: this host was late by `late` [s]."""
    return f'not judged: this host was late by {late * 1e3:.0f} ms ({what})'
