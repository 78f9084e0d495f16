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

"""The simulated controller's own lateness, written for ``rubber-rig conformance --sim`` (docs/protocol.md,
"Host timing"): a real controller has a CPU of its own; the simulator shares this host's, and every deadline it
missed because of that is this host's lateness, not the controller's it stands for.
"""
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
