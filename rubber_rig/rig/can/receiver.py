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

"""Event-driven reception: a thread blocks on the bus and wakes the driver's owner when a batch of samples is in.

Polling the bus every 2 ms from a ROS timer woke rig_driver's executor 500 times a second, and each executor
wake-up costs far more than reading a frame (rclpy rebuilds its wait set every time: about 0.4 ms of CPU per
wake-up measured on this machine, issue 37). Here a thread of its own blocks in the bus's ``recv`` (a select on
the socket for SocketCAN and udp_multicast, a condition for the simulated buses: no CPU while nothing arrives),
keeps every frame in arrival order, and calls ``wake()`` once ``frames_per_wake`` sample frames have arrived since
the last call: with one batch's worth of frames, the executor wakes once per batch it will publish, not once per
poll. The frames themselves are decoded by the driver's own poll(), in the thread that owns the driver: nothing
of the driver's state is touched here.

What the thread cannot do is notice that nothing arrives: a silent bus never wakes it. The watchdog still needs
poll() called periodically (RigDriver.tick_period), so the owner keeps a slow timer for that.
"""
from __future__ import annotations

import collections
import threading
from typing import Callable

RECV_TIMEOUT = 0.1   # [s] the longest a blocked receive waits before it looks whether it must stop


class BusReceiver:
    """Reads python-can ``bus`` in a thread; frames wait in arrival order for :meth:`take`.

    ``counted`` (a set of arbitration ids, standard frames) are the frames that carry samples; ``wake()`` is called
    (from the receiving thread; it must be thread-safe, e.g. a ROS guard condition's trigger) after every
    ``frames_per_wake`` of them. ``on_error(exc)`` hears a receive that raised (the bus went away); the thread
    then stops, and the owner's periodic poll finds the bus silent. ``on_start()`` runs first in the thread (e.g.
    giving it an OS name that ``top -H`` and the benchmarks see: rubber_rig.cpu).
    """

    def __init__(self, bus, counted: set[int], frames_per_wake: int, wake: Callable[[], None],
                 on_error: Callable[[BaseException], None] = lambda exc: None, on_start: Callable[[], None] = None):
        if frames_per_wake < 1:
            raise ValueError(f'frames_per_wake must be at least 1, not {frames_per_wake}')
        self.bus, self.counted, self.frames_per_wake = bus, set(counted), int(frames_per_wake)
        self.wake, self.on_error, self.on_start = wake, on_error, on_start
        self.frames = collections.deque()   # received, not yet taken (append/popleft are atomic: no lock)
        self.wakes = 0                       # how often wake() was called
        self.error: BaseException | None = None   # why the thread stopped on its own (set once, by the thread)
        self.said = False                          # the owner has reported the error (FrameIO.receive_all)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='can-receive', daemon=True)

    def start(self) -> 'BusReceiver':
        self._thread.start()
        return self

    def take(self) -> list:
        """Every frame received since the last call, oldest first."""
        frames, out = self.frames, []
        while frames:
            out.append(frames.popleft())
        return out

    def stop(self, timeout: float = 2 * RECV_TIMEOUT) -> None:
        """Stop reading (before the bus is shut down: a receive must not run on a closed bus)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        recv, keep, counted, stop = self.bus.recv, self.frames.append, self.counted, self._stop
        since_wake = 0
        try:
            if self.on_start is not None:
                self.on_start()
            while not stop.is_set():
                msg = recv(RECV_TIMEOUT)
                while msg is not None:        # everything already waiting, without blocking in between
                    keep(msg)
                    if msg.arbitration_id in counted and not msg.is_extended_id:
                        since_wake += 1
                    msg = recv(0)
                if since_wake >= self.frames_per_wake:
                    since_wake = 0
                    self.wakes += 1
                    self.wake()
        except Exception as exc:   # noqa: BLE001 - the bus went away: said once, the periodic poll takes over
            if not stop.is_set():
                self.error = exc
                self.on_error(exc)
