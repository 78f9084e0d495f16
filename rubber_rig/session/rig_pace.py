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

"""RigPace: which sample a running rig plays now, on the stream owner's own clock.

The excitation keeps its setpoints ``lead`` ahead of the rig. The latest *measured* sample it has received lags
the rig by the whole sample path (the driver's batching, its executor, DDS, the excitation's executor), and on a
busy computer that lag grows exactly when the reserve is needed: the batches arrive late, and after a stall of the
excitation's executor the timer may stream before the backlog of samples is read. Every stalled moment then
counted twice, once in the rig's queue and once in the stale measurement, and a 0.5 s stall left 87 ms of a 0.7 s
lead (issue 34). A rig plays one sample per sample period whatever the host does, so the owner's clock tells how
far it has come since the samples it knows of: each batch that arrives at `now` ending at sample `end` says the
rig's sample 0 was at most ``now - end / fs`` on this clock; the earliest such origin over the last few seconds
(the batch that came fastest) gives the rig's current sample as ``(now - origin) * fs``.

That alone still counts the fastest batch's own lag. A batch's stamp (the bus time its samples were measured,
on time.time()'s scale like the owner's ROS clock on the same computer) removes it, when it is credible: a stamp
origin is taken only if the batch arrived after it was measured and at most MAX_STAMP_LAG later. A clock of
another computer (or simulated time) further off than that is ignored, and one off by less makes the stream
longer (latency; ProgramSession.ahead_of caps it at one lead past the measurement), never shorter: the arrival
bound stays. The bound is long because a loaded computer's sample path lags that long for seconds on end (a
second suite on the same cores), when the arrival times alone no longer tell the rig's pace.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Optional

#: [s] how long a batch's arrival vouches for the rig's pace (long beside a stall, short beside clock drift:
#: 100 ppm over 5 s is 0.5 ms)
WINDOW = 5.0
#: [s] the longest lag from a batch's stamp to its arrival that is taken as the sample path's, not a clock offset
MAX_STAMP_LAG = 1.0


class RigPace:
    """The sample a rig at `sample_rate` [Hz] plays now, from when its sample batches arrived (clock [s])."""

    def __init__(self, sample_rate: float, window: float = WINDOW):
        self.fs, self.window = float(sample_rate), float(window)
        self._origins: deque = deque()     # (arrival [s], origin [s]), origins increasing: a sliding minimum
        self.last_arrival: Optional[float] = None   # [s] when the latest batch arrived

    def reset(self) -> None:
        """A new stream (the rig may have stood idle, and its sequence jumped): forget the pace."""
        self._origins.clear()
        self.last_arrival = None

    def observe(self, end: int, now: float, stamp: Optional[float] = None) -> None:
        """A batch of samples up to (not including) sequence `end` arrived at `now` [s]; stamp [s]: when its last
        sample (end - 1) was measured, on the owner's clock's scale (None: unknown).
        """
        self.last_arrival = float(now)
        origin = float(now) - int(end) / self.fs
        if stamp is not None and math.isfinite(stamp):
            measured = float(stamp) - (int(end) - 1) / self.fs
            if 0.0 <= origin - measured <= MAX_STAMP_LAG:
                origin = measured
        q = self._origins
        while q and q[-1][1] >= origin:
            q.pop()
        q.append((float(now), origin))
        while q[0][0] < now - self.window:
            q.popleft()

    def playing(self, now: float) -> Optional[int]:
        """The sequence a rig that kept its pace plays at `now` [s]; None before any batch vouched for it (or
        after none did for the window).
        """
        q = self._origins
        while q and q[0][0] < now - self.window:
            q.popleft()
        if not q:
            return None
        return math.floor((now - q[0][1]) * self.fs + 1e-9)
