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

"""The embedded simulator's lateness: how far this host has kept it behind its schedule, for the driver beside it.

A real controller has its own CPU: when its feedback stops, it stopped, and the host's watchdog must fault. The
simulated controller that rig_driver runs in a thread of its own process stands for such a controller, but it
shares this host's CPU: a busy computer that does not schedule it for 0.3 s silences its feedback and heartbeats
for 0.3 s, and that silence is the host's, not the rig's. The simulator knows (it wakes after its deadline and
ticks what was due at once); this ledger tells the driver how far its output lags its schedule *now*, and the
driver judges the controller's silence on the simulator's schedule instead of the wall clock (Supervisor.watchdog).

The lag, not the sum of late wake-ups: a simulator woken 2 ms late every 3 ms keeps its output within 2 ms of its
schedule, and summing those 2 ms would excuse two thirds of any real silence (a silent_controller fault went
unnoticed that way). After a late wake-up its catch-up burst is still on the bus, the lowest-priority frames last:
the lag it caught up decays at the rate of real time (a bus below full load carries the burst in less time than
it stands for). Only the embedded simulator keeps a ledger: a real controller's driver has none, and no discount.
"""
from __future__ import annotations

import math
import threading


class LatenessLedger:
    """How far [s] the simulated controller's output lags its schedule, on its clock (the driver's, one process).

    A current overdue counts up to ``cap`` [s]: a simulator that has not woken for longer than that is not starved
    but stuck (or dead), and its silence faults the rig like a real controller's. A stopped simulator lags nothing.
    """

    def __init__(self, cap: float = 1.0):
        self.cap = float(cap)
        self._lock = threading.Lock()
        self._due = math.inf          # [s] clock time its next deadline (a tick, or the idle housekeeping) is due
        self._caught = (0.0, -math.inf)   # (lateness [s], clock time [s]) of the latest late wake-up

    def woke(self, now: float, late: float, due_next: float) -> None:
        """The simulator woke at `now` [s], `late` [s] after its deadline (0: on time), did what was due, and is next
        due at `due_next` [s].
        """
        with self._lock:
            if late > 0.0:
                self._caught = (min(float(late), self.cap), float(now))
            self._due = float(due_next)

    def stopped(self) -> None:
        """The simulator no longer serves the bus (stopped, or its thread ended): nothing it misses is excused."""
        with self._lock:
            self._due, self._caught = math.inf, (0.0, -math.inf)

    def lag(self, now: float) -> float:
        """How far [s] behind its schedule the simulator's output reaches the bus at `now` [s]: its current overdue
        (up to ``cap``), or what is left of the latest catch-up's burst.
        """
        with self._lock:
            late, at = self._caught
            return max(min(self.cap, now - self._due), late - (now - at), 0.0)
