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

"""The simulated controller's own lateness, which is this host's: two records of it, one per reader.

A real controller has a CPU of its own; the simulator shares this host's, and every deadline it missed because of
that is this host's lateness, not the controller's it stands for. Two readers need it, each in its own form:

- ``LatenessLog``: the missed deadlines as 'start end' lines in a file, for ``rubber-rig conformance --sim`` with
  the simulator in a process of its own (docs/protocol.md, "Host timing").
- ``LatenessLedger``: how far the embedded simulator's output lags its schedule *now*, for rig_driver beside it in
  one process.

The ledger: a real controller's feedback that stops means it stopped, and the host's watchdog must fault. The
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
import time
from typing import Callable

from ..conformance.host_timing import SIM_LATE_MIN, DropWatch

DROPS_PERIOD = 0.005    # [s] the socket's drop count is read at most this often


class LatenessLog:
    """Missed deadlines as 'start end' lines (wall-clock s, `wall`: time.time()) in `file` (a text file open for
    append; None: nothing is recorded), each SIM_LATE_MIN or more; with `drops` (a callable: the count of frames
    the controller's socket dropped so far, None if unknown; can.udp_socket.dropped) also each stretch in which
    that count grew, read at most every DROPS_PERIOD at a wake-up.
    """

    def __init__(self, wall: Callable[[], float] = time.time, drops: Callable[[], int] = None):
        self.file, self.drops = None, drops
        self._wall = wall
        self._drop_watch, self._next_drops = DropWatch(), 0.0

    def missed(self, late: float, noticed: float = None):
        """A deadline missed by `late` [s], noticed at wall-clock time `noticed` (default now): a window from the
        deadline until now (the frames due meanwhile were sent by now, in a burst: their timing is this host's).
        """
        if self.file is not None and late >= SIM_LATE_MIN:
            t = self._wall()
            self.file.write(f'{(t if noticed is None else noticed) - late:.6f} {t:.6f}\n')

    def woke(self, asked: float, wait: float, msg) -> None:
        """The wait for a frame asked at wall-clock time `asked` [s] for `wait` [s] returned now with `msg` (or
        None): a wake-up later than the timeout, or a frame that arrived during the wait (its receive time stamp,
        time.time()'s scale) read later than it arrived, is this host's lateness. A wake-up that starts a stream
        shows its lateness here only: the stream's deadlines start from it.
        """
        if self.file is None:
            return
        now = self._wall()
        if msg is None:
            self.missed(now - asked - wait)
        elif msg.timestamp:
            self.missed(now - max(msg.timestamp, asked))
        if self.drops is not None and now >= self._next_drops:
            self._next_drops = now + DROPS_PERIOD
            lost = self._drop_watch.update(now, self.drops())
            if lost:       # frames (setpoints, heartbeats) the socket lost while this process did not read it
                self.file.write(f'{lost[0]:.6f} {lost[1]:.6f}\n')

    def close(self):
        if self.file is not None:
            self.file.close()
            self.file = None


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
