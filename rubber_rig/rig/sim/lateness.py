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

"""The embedded simulator's lateness: how long this host kept it from its deadlines, for the driver beside it.

A real controller has its own CPU: when its feedback stops, it stopped, and the host's watchdog must fault. The
simulated controller that rig_driver runs in a thread of its own process stands for such a controller, but it
shares this host's CPU: a busy computer that does not schedule it for 0.3 s silences its feedback and heartbeats
for 0.3 s, and that silence is the host's, not the rig's. The simulator already knows (it wakes after its
deadline and ticks what was due at once); this ledger tells the driver, which then judges the controller's
silence only over the time the simulator could have spoken (Supervisor.starved). Only the embedded simulator
keeps one: a real controller's driver has no ledger and no discount.
"""
from __future__ import annotations

import math
import threading


class LatenessLedger:
    """Time [s] the simulated controller was kept from its deadlines, on its clock (the driver's, in one process).

    ``behind(now)`` is the sum of every missed deadline it caught up with plus how far it is behind now, each
    current overdue counted up to ``cap`` [s]: a simulator that has not woken for longer than that is not starved
    but stuck (or dead), and its silence faults the rig like a real controller's. A stopped simulator is not
    behind at all.
    """

    def __init__(self, cap: float = 1.0):
        self.cap = float(cap)
        self._lock = threading.Lock()
        self._missed = 0.0            # [s] deadlines missed and caught up with
        self._due = math.inf          # [s] clock time its next deadline (a tick, or the idle housekeeping) is due
        self._running = True

    def due(self, at: float) -> None:
        """The simulator's next deadline is at `at` [s] on its clock (it waits until then unless a frame comes)."""
        with self._lock:
            self._due = float(at)

    def missed(self, late: float, due_next: float) -> None:
        """The simulator woke `late` [s] after a deadline, caught up, and is next due at `due_next` [s]."""
        with self._lock:
            self._missed += max(0.0, float(late))
            self._due = float(due_next)

    def stopped(self) -> None:
        """The simulator no longer serves the bus (stopped, or its thread ended): nothing it misses is excused."""
        with self._lock:
            self._running, self._due = False, math.inf

    def behind(self, now: float) -> float:
        """Time [s] the simulator has been kept from its deadlines up to `now` [s] (non-decreasing while it runs,
        up to the ``cap`` on the current overdue).
        """
        with self._lock:
            if not self._running:
                return self._missed
            return self._missed + min(self.cap, max(0.0, now - self._due))
