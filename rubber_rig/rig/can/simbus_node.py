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

"""One node's end of a simulated CAN bus segment (simbus.BusMedium): a python-can bus whose frames the medium
schedules with real bit timing, and the arbitration order of frames on the wire.
"""
import math
import time
from collections import deque
from typing import TYPE_CHECKING

import can

if TYPE_CHECKING:
    from .simbus import BusMedium

_INF = math.inf
# shortest wait [s] on the condition when a moment is due but not yet past on the clock (avoids a busy loop)
_MIN_WAIT = 1e-5


def arbitration_key(arbitration_id: int, extended: bool = False, remote: bool = False) -> int:
    """The arbitration field of a frame as a 32-bit number whose order is the bus's priority order (lower wins).

    Standard frame: identifier (11 bits), RTR, IDE = 0. Extended frame: base identifier (11 bits), SRR = 1,
    IDE = 1, identifier extension (18 bits), RTR. Dominant (0) bits win bit by bit, so a standard frame beats
    an extended frame with the same base identifier and a data frame beats a remote frame with the same
    identifier (CAN FD frames have no remote frames: RRS is always dominant).
    """
    if extended:
        return ((arbitration_id >> 18) << 21) | 0x180000 | ((arbitration_id & 0x3FFFF) << 1) | int(remote)
    return (arbitration_id << 21) | (int(remote) << 20)


class TimedBus(can.BusABC):
    """One node's end of a :class:`BusMedium`, a python-can bus (make it with :meth:`BusMedium.attach`).

    send(msg) queues a frame for the bus and returns at once (timeout is accepted for BusABC and not used: a
    full transmit queue raises CanOperationError at once, as SocketCAN's ENOBUFS); recv(timeout) returns the
    next frame of another node once its transmission has ended on the medium's clock (timeout [s] of real
    time; None waits forever, 0 polls). Counters: frames_sent (transmissions completed), frames_dropped,
    frames_queued, max_queue_delay [s].
    """

    def __init__(self, medium: 'BusMedium', name: str = '', can_filters=None, **kwargs):
        self.medium = medium
        self._rx = deque()                  # (arrival [s] on the medium's clock, frame), in arrival order
        self._txq = deque()                 # heap entries of the frames waiting for the bus, in queued order
        self._queued = 0
        self._sent = 0
        self._dropped = 0
        self._max_delay = 0.0
        self._open = True
        self._can_protocol = can.CanProtocol.CAN_FD if medium.fd else can.CanProtocol.CAN_20
        self.receive_own_messages = False
        super().__init__(channel=medium.name, can_filters=can_filters, **kwargs)
        self.name = medium._attach(self, name)
        self.channel_info = f'{medium.channel_info}, node {self.name}'

    def _check_open(self):
        if not self._open:
            raise can.CanOperationError(f'{self.name} is shut down (detached from {self.medium.name})')

    def send(self, msg: can.Message, timeout: float = None) -> None:
        medium = self.medium
        fd, data = msg.is_fd, bytes(msg.data)
        frame = (msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame, msg.dlc, data, fd,
                 fd and msg.bitrate_switch, msg.error_state_indicator)
        with medium._lock:
            self._check_open()
            # (duration, arbitration key) of each shape of frame is worked out once
            timing = medium._timing.get(frame[:3] + (len(data), fd, frame[6], msg.is_error_frame))
            if timing is None:
                timing = medium._timing[frame[:3] + (len(data), fd, frame[6], msg.is_error_frame)] = (
                    medium._duration(msg), arbitration_key(msg.arbitration_id, msg.is_extended_id,
                                                           msg.is_remote_frame))
            now = medium._advance()
            if self._queued >= medium.tx_queue:
                self._dropped += 1
                medium._dropped += 1
                raise can.CanOperationError(f'{self.name}: transmit buffer full ({medium.tx_queue} frames waiting '
                                            f'for {medium.name}); frame 0x{msg.arbitration_id:X} dropped')
            medium._enqueue(self, now, timing[0], frame, timing[1])

    def recv(self, timeout: float = None):
        """BusABC.recv; a poll (timeout 0) of a node without filters - every poll of a stepped rig - goes straight
        to the medium (no timing and filtering loop around it, the same frame).
        """
        if timeout == 0 and self._filters is None:
            medium = self.medium
            with medium._lock:
                self._check_open()
                now = medium._advance()
                rx = self._rx
                if rx and rx[0][0] <= now:
                    return self._message(*rx.popleft())
            if medium.threaded:
                time.sleep(0)           # as _recv_internal: let the other nodes' threads run
            return None
        return super().recv(timeout)

    def _message(self, arrival: float, frame: tuple) -> can.Message:
        """The received frame, stamped with its arrival [s] on time.time()'s scale."""
        arb_id, extended, remote, dlc, data, fd, brs, esi = frame
        return can.Message(timestamp=arrival + self.medium.time_offset, arbitration_id=arb_id,
                           is_extended_id=extended, is_remote_frame=remote, dlc=dlc, data=data, is_fd=fd,
                           bitrate_switch=brs, error_state_indicator=esi, channel=self.medium.name, is_rx=True)

    def _recv_internal(self, timeout: float = None):
        medium = self.medium
        deadline = None if timeout is None else time.monotonic() + timeout
        with medium._cond:
            while True:
                self._check_open()
                now = medium._advance()
                rx = self._rx
                if rx and rx[0][0] <= now:
                    return self._message(*rx.popleft()), False
                # the next moment anything can arrive here: a frame on the bus, or the next arbitration
                wait = (rx[0][0] if rx else medium._next_arb) - now
                if deadline is not None:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        break
                    wait = min(wait, left)
                medium._cond.wait(None if wait == _INF else max(wait, _MIN_WAIT))
        # nothing yet: let the other nodes' threads run (a host polling in a tight loop would otherwise hold
        # the GIL and starve the controller thread, which a real controller's own CPU never is); a medium whose
        # nodes are all stepped by one thread on a simulated clock (threaded False) has no one to yield to
        if medium.threaded:
            time.sleep(0)
        return None, False

    def flush_tx_buffer(self) -> None:
        """Discard the frames this node has queued that have not started on the bus."""
        with self.medium._lock:
            self.medium._advance()
            self.medium._discard(self)

    def shutdown(self) -> None:
        """Detach from the medium: queued frames are discarded, the other nodes keep working."""
        if not self._open:
            return
        self._open = False
        self.medium._detach(self)
        super().shutdown()

    def _counter(self, name: str):
        with self.medium._lock:
            self.medium._advance()
            return getattr(self, name)

    @property
    def frames_sent(self) -> int:
        """Frames of this node whose transmission has completed."""
        return self._counter('_sent')

    @property
    def frames_dropped(self) -> int:
        """Frames refused because the transmit queue was full."""
        return self._counter('_dropped')

    @property
    def frames_queued(self) -> int:
        """Frames waiting for the bus now."""
        return self._counter('_queued')

    @property
    def max_queue_delay(self) -> float:
        """Longest wait [s] of a frame of this node between send and the start of its transmission."""
        return self._counter('_max_delay')
