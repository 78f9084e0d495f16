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

"""Several periodic duties of a node run from one timer (ROS-free): which of them are due at ``now``.

Every timer of a node is an entity its executor waits on and a wake-up of its own when it fires; a node that beats,
watches its peers, publishes status and diagnostics and looks at the graph on five timers wakes five times where
once would do (issue 37). A node keeps one timer, ticking at :meth:`Cadence.tick_period` (the shortest period), and
asks the cadence on each tick which duties are due, with ``now`` from its own clock (simulated time in a test).

A duty is due at its first tick (a node says at once what it is) and then whenever ``period`` has passed since it
was last due, measured from when it was due, not from when it ran: a tick late by a little does not stretch the
period of every later one. A tick so late that a whole period or more was missed runs the duty once and starts its
period again from ``now`` (no burst of catch-up runs after a stall).
"""
from __future__ import annotations

import math


class Cadence:
    """The duties ``periods`` (name -> period [s], > 0) of one node, run from one timer.

    >>> c = Cadence({'status': 0.1, 'diagnostics': 1.0})
    >>> c.due(0.0), c.due(0.1), c.due(0.15), c.due(1.0)
    (['status', 'diagnostics'], ['status'], [], ['status', 'diagnostics'])
    """

    def __init__(self, periods: dict[str, float]):
        if not periods:
            raise ValueError('a cadence needs at least one duty')
        for name, period in periods.items():
            if not period > 0 or not math.isfinite(period):
                raise ValueError(f'duty {name!r}: period must be a positive number of seconds, not {period!r}')
        self.periods = dict(periods)
        self._next: dict[str, float | None] = dict.fromkeys(periods)   # when each is due next (None: at once)
        # a tick up to this fraction of the timer's period early still counts (the timer and the clock read
        # in the callback are not the same instant; without it a duty at the tick period would skip every other tick)
        self._slack = 0.25 * self.tick_period()

    def tick_period(self) -> float:
        """The period [s] the node's one timer must tick at: the shortest duty's."""
        return min(self.periods.values())

    def due(self, now: float) -> list[str]:
        """The duties due at ``now`` [s] (in the order they were given), marked as run."""
        out = []
        for name, period in self.periods.items():
            when = self._next[name]
            if when is not None and now < when - self._slack:
                continue
            out.append(name)
            self._next[name] = now + period if when is None or now >= when + period else when + period
        return out
