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

"""A simulated CAN bus segment with real bit timing, for in-process nodes that talk through python-can.

:class:`BusMedium` is one bus segment; :meth:`BusMedium.attach` gives each node (the simulated controller, the
host driver, a logger) its own :class:`TimedBus`, a python-can ``BusABC``. Unlike python-can's virtual
interface, the medium behaves like a loaded CAN bus:

* each frame occupies the bus for its duration (:func:`rubber_rig.rig.can.timing.frame_time`, worst-case bit
  stuffing; CAN FD frames with bit-rate switch run their data phase at the data bitrate);
* frames go out one at a time. Each node sends its own frames in the order it queued them (a FIFO transmit
  queue, as SocketCAN's); when the bus becomes free, arbitration picks, among the frames at the head of each
  node's queue at that moment, the one with the lowest identifier (bitwise, as on the wire: an 11-bit
  identifier beats a 29-bit one with the same base identifier, a data frame beats a remote frame); equal
  identifiers go in the order they were queued;
* a frame reaches every other node when its transmission ends, never earlier, with that moment as timestamp;
* each node's transmit queue holds ``tx_queue`` frames; a send on a full queue fails like SocketCAN's ENOBUFS,
  so an offered load above the bus capacity first delays frames, then loses them.

There is no background thread: each call advances the schedule to ``clock()`` (lazy, event-driven
evaluation), so a fake clock gives exact, repeatable timing in tests. An arbitration moment is decided once the
clock has passed it, so frames queued at that very instant (same clock reading) take part in it.
"""
import heapq
import itertools
import math
import threading
import time
from collections import deque

import can

from .simbus_node import TimedBus, arbitration_key
from .timing import frame_bits, frame_time

__all__ = ['BusMedium', 'TimedBus', 'arbitration_key']

_INF = math.inf
_medium_names = itertools.count()


class BusMedium:
    """One simulated CAN bus segment shared by the nodes attached to it (in this process).

    bitrate and data_bitrate [bit/s] (the data bitrate is used by CAN FD frames with bit-rate switch; fd False
    makes a classic-only segment that refuses FD frames), tx_queue [frames] the transmit queue of each node,
    clock a function returning seconds [s] (time.monotonic, or a fake clock in tests; waits in recv assume it
    runs at real speed), load_window [s] how far back :meth:`load` can look, threaded False when one thread
    steps every node on a simulated clock (an empty receive then never yields the GIL), time_offset [s] what
    turns clock() into frame timestamps (default: time.time()'s scale; a simulated clock gives its own). Thread
    safe.
    Delivered frames carry their arrival time on time.time()'s scale: clock() + time_offset [s].
    """

    def __init__(self, bitrate: float = 1_000_000, data_bitrate: float = 5_000_000, fd: bool = True,
                 tx_queue: int = 256, clock=time.monotonic, load_window: float = 1.0, name: str = None,
                 threaded: bool = True, time_offset: float = None):
        if bitrate <= 0 or (data_bitrate is not None and data_bitrate <= 0):
            raise ValueError(f'bitrates must be positive, not {bitrate}, {data_bitrate} bit/s')
        if tx_queue < 1:
            raise ValueError(f'a transmit queue holds at least one frame, not {tx_queue}')
        if load_window <= 0:
            raise ValueError(f'load_window must be positive, not {load_window} s')
        self.bitrate = bitrate
        self.data_bitrate = data_bitrate if fd else None
        self.fd = fd
        self.tx_queue = tx_queue
        self.load_window = load_window
        self.name = name or f'simbus{next(_medium_names)}'
        self.threaded = threaded
        rates = f'{bitrate:g}/{data_bitrate or bitrate:g} bit/s CAN FD' if fd else f'{bitrate:g} bit/s classic CAN'
        self.channel_info = f'simulated CAN bus {self.name} ({rates})'
        self._clock = clock
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._now = clock()
        # delivered timestamps are on time.time()'s scale, like those of the hardware interfaces
        self.time_offset = time.time() - self._now if time_offset is None else float(time_offset)
        self._nodes = []
        self._node_names = itertools.count()
        # frames waiting for the bus: (arbitration key, enqueue counter, enqueue time, duration, node, frame)
        self._heap = []
        self._counter = itertools.count()
        self._durations = {}
        self._timing = {}                   # frame shape -> (duration [s], arbitration key) (TimedBus.send)
        self._free = self._now              # [s] the end of the last transmission
        self._next_arb = _INF               # [s] the next arbitration moment (inf: nothing queued)
        self._inflight = None               # (node, start, end) of the last transmission while it may run
        self._intervals = deque()           # (start, end) [s] of the transmissions of the last load_window
        self._interval_sum = 0.0            # [s] their total duration
        self._transmitted = 0
        self._dropped = 0
        self._discarded = 0
        self._busy = 0.0                    # [s] bus time of the completed transmissions
        self._max_delay = 0.0

    def __repr__(self) -> str:
        return f'BusMedium({self.channel_info})'

    def attach(self, name: str = '') -> 'TimedBus':
        """A new node (python-can bus end) on this segment; it hears the frames that start after now."""
        return TimedBus(self, name)

    def load(self, window: float = None) -> float:
        """Busy fraction [-] of the bus over the last window [s] (default load_window, at most load_window),
        from the frames actually transmitted (a frame on the bus now counts up to now).
        """
        window = self.load_window if window is None else window
        if not 0 < window <= self.load_window:
            raise ValueError(f'the load window must be in (0, {self.load_window}] s, not {window}')
        with self._lock:
            now = self._advance()
            lo = now - window
            if window == self.load_window:
                return self._window_load(now, lo) / window
            busy = 0.0
            for start, end in reversed(self._intervals):
                if end <= lo:
                    break
                busy += min(end, now) - max(start, lo)
        return busy / window

    def _window_load(self, now: float, lo: float) -> float:
        """Busy time [s] in (lo, now] over the whole load_window: the running sum of the transmissions kept,
        less what of them lies outside (the oldest before lo, the one in flight after now).
        """
        intervals = self._intervals
        while intervals and intervals[0][1] <= lo:     # wholly before the window: no longer kept
            start, end = intervals.popleft()
            self._interval_sum -= end - start
        busy = self._interval_sum
        if intervals:
            start, end = intervals[0]
            if start < lo:
                busy -= lo - start
            start, end = intervals[-1]
            if end > now:
                busy -= end - max(start, now)
        return max(busy, 0.0)

    @property
    def stats(self) -> dict:
        """Counters of the segment up to now: frames_transmitted (completed), frames_dropped (transmit queue
        full, all nodes), frames_discarded (queued on a node that shut down or flushed), frames_queued (waiting
        for the bus now), busy_time [s] (bus time used so far), max_queue_delay [s] (longest wait of a frame
        between send and the start of its transmission), nodes (attached), time [s] (on clock).
        """
        with self._lock:
            now = self._advance()
            busy = self._busy
            if self._inflight is not None:
                busy += now - self._inflight[1]
            return {'frames_transmitted': self._transmitted, 'frames_dropped': self._dropped,
                    'frames_discarded': self._discarded, 'frames_queued': sum(n._queued for n in self._nodes),
                    'busy_time': busy,
                    'max_queue_delay': self._max_delay, 'nodes': len(self._nodes), 'time': now}

    # --- the schedule (all below run with self._lock held) ---

    def _duration(self, msg: can.Message) -> float:
        """Duration [s] of msg on this bus; CanOperationError when this bus cannot carry it."""
        if msg.is_error_frame:
            raise can.CanOperationError(f'{self.name}: a node does not transmit error frames as messages')
        fd = msg.is_fd
        key = (len(msg.data), fd, fd and msg.bitrate_switch, msg.is_extended_id, msg.is_remote_frame)
        duration = self._durations.get(key)
        if duration is not None:
            return duration
        if fd and not self.fd:
            raise can.CanOperationError(f'{self.name} is a classic CAN bus (fd=False); it cannot carry the CAN FD '
                                        f'frame 0x{msg.arbitration_id:X} ({len(msg.data)} bytes)')
        if fd and msg.is_remote_frame:
            raise can.CanOperationError(f'{self.name}: CAN FD has no remote frames (0x{msg.arbitration_id:X})')
        n = 0 if msg.is_remote_frame else len(msg.data)
        brs = key[2]
        try:
            duration = frame_time(n, self.bitrate, self.data_bitrate, fd=fd, bitrate_switch=brs)
        except ValueError as e:
            raise can.CanOperationError(f'{self.name}: {e}') from e
        if msg.is_extended_id:
            # the 29-bit identifier lengthens the arbitration field, which runs at the nominal bitrate
            duration += (frame_bits(n, fd, brs, extended=True)[0] - frame_bits(n, fd, brs)[0]) / self.bitrate
        self._durations[key] = duration
        return duration

    def _advance(self) -> float:
        """Run the schedule up to the clock's now [s] and return now."""
        now = self._clock()
        if now < self._now:
            now = self._now                 # a clock that steps back must not undo decided moments
        else:
            self._now = now
        if self._next_arb < now:
            self._run(now)
        elif self._inflight is not None and self._inflight[2] <= now:
            self._complete()
        return now

    def _complete(self):
        node, start, end = self._inflight
        node._sent += 1
        self._transmitted += 1
        self._busy += end - start
        self._inflight = None

    def _run(self, now: float):
        """Start, one after another, the transmissions whose arbitration moment is before now."""
        heap, nodes, intervals = self._heap, self._nodes, self._intervals
        t = self._next_arb
        while t < now:
            if self._inflight is not None:
                self._complete()
            _, _, enqueued, duration, node, frame = heapq.heappop(heap)
            node._queued -= 1
            txq = node._txq
            txq.popleft()
            if txq:   # the node's next frame is its new head in the arbitration
                heapq.heappush(heap, txq[0])
            delay = t - enqueued
            if delay > node._max_delay:
                node._max_delay = delay
                if delay > self._max_delay:
                    self._max_delay = delay
            end = t + duration
            for other in nodes:
                if other is not node:
                    other._rx.append((end, frame))
            intervals.append((t, end))
            self._interval_sum += duration
            horizon = t - self.load_window
            while intervals[0][1] <= horizon:
                start, stop = intervals.popleft()
                self._interval_sum -= stop - start
            self._inflight = (node, t, end)
            self._free = end
            t = end if heap else _INF
        self._next_arb = t
        if self._inflight is not None and self._inflight[2] <= now:
            self._complete()

    def _enqueue(self, node: 'TimedBus', now: float, duration: float, frame: tuple, key: int):
        # each node sends its frames in the order it queued them (a FIFO transmit queue, as SocketCAN's); only the
        # head of each node's queue takes part in the arbitration between nodes
        entry = (key, next(self._counter), now, duration, node, frame)
        node._txq.append(entry)
        if len(node._txq) == 1:
            heapq.heappush(self._heap, entry)
        node._queued += 1
        if self._next_arb == _INF:
            # the bus was idle or about to be: this frame makes a new arrival possible, so wake the receivers
            self._next_arb = max(self._free, now)
            self._cond.notify_all()

    def _discard(self, node: 'TimedBus'):
        """Drop the frames node has queued (not yet on the bus)."""
        if not node._queued:
            return
        self._heap = [entry for entry in self._heap if entry[4] is not node]
        heapq.heapify(self._heap)
        node._txq.clear()
        self._discarded += node._queued
        node._queued = 0
        # without the discarded frames the next moment is when the bus is free and a remaining frame is queued
        self._next_arb = max(self._free, min(entry[2] for entry in self._heap)) if self._heap else _INF
        self._cond.notify_all()

    def _attach(self, node: 'TimedBus', name: str) -> str:
        """Add node to the receivers and return its name (a numbered one when name is empty)."""
        with self._lock:
            self._advance()                 # node hears the frames that start from now on
            self._nodes.append(node)
            return name or f'{self.name}.node{next(self._node_names)}'

    def _detach(self, node: 'TimedBus'):
        with self._lock:
            self._advance()                 # frames of node already on the bus still reach the others
            if node in self._nodes:
                self._nodes.remove(node)
            self._discard(node)
            node._rx.clear()
            self._cond.notify_all()         # a recv blocked on node raises
