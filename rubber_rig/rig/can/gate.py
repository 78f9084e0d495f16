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


"""The stream gate: which setpoint batches reach the driver's queue, and what happens to the rest.

The command channel a batch arrived on (not its stream id or sender name, which anyone can copy) says who sent
it. A batch from the open stream's owner goes to RigDriver.queue_setpoints, which checks continuity and the
envelope; a batch from anyone else is refused and counted (RigDriver.refuse). A channel that is not the owner's
and sends more than MUTE_AFTER batches within a second is muted for MUTE_FOR seconds (never the owner's own
channel, whatever arrives on it: muting it would stop the owner's program for the forger): each refused batch still
costs the executor a callback, and on a 2-core computer a flood of them (2000 in 0.3 s) delayed the owner's
batches past stream_timeout. An owner streams at most ~100 batches/s (10 ms batches). The node only carries
out the verdict (destroys a muted channel's subscription, logs); it never writes the driver's state.
"""
import time
from dataclasses import dataclass
from typing import Callable

MUTE_AFTER = 200    # refused batches within 1 s that mute a channel
MUTE_FOR = 10.0     # [s]


@dataclass(frozen=True)
class Admission:
    """The verdict on one batch. action: 'queued', 'refused' or 'mute' (refused, and the channel is to be muted
    now); why: the reason for a refusal ('' when queued).
    """

    action: str
    why: str = ''


class StreamGate:
    """Admits setpoint batches into `driver` (a RigDriver) by the channel they came on; counts and mutes."""

    def __init__(self, driver, clock: Callable[[], float] = time.monotonic):
        self.driver, self._clock = driver, clock
        self._window: dict[str, list] = {}     # channel -> [start of its 1 s window, batches refused in it]
        self._muted: dict[str, float] = {}     # channel -> clock time until which it is muted

    def offer(self, channel: str, source: str, first_sequence: int, displacement, stream_id: int,
              end_of_stream: bool = False) -> Admission:
        """Queue a batch [m] from `channel` if it is the open stream owner's (and the driver takes it)."""
        drv = self.driver
        grant = drv.stream
        if grant is not None and (channel != grant.owner or source != grant.owner):
            why = f'sender {source or "(unnamed)"} on the channel of {channel} is not the stream owner {grant.owner}'
            drv.refuse(len(displacement), why)
            now = self._clock()
            window = self._window.setdefault(channel, [now, 0])
            if now - window[0] > 1.0:
                window[:] = [now, 0]
            window[1] += 1
            # never the owner's own channel: a forger that floods it under another sender name would otherwise
            # mute the owner and kill its program (issue 35: 201 batches did); those batches are refused one by one
            if window[1] > MUTE_AFTER and channel != grant.owner:
                window[1] = 0
                self._muted[channel] = now + MUTE_FOR
                drv.count('channels_muted')
                return Admission('mute', why)
            return Admission('refused', why)
        if not drv.queue_setpoints(first_sequence, displacement, stream_id):
            return Admission('refused', drv.refusal or drv.status.state)
        if end_of_stream:
            drv.end_stream(stream_id)
        return Admission('queued')

    def muted(self, channel: str) -> bool:
        """Whether `channel` is muted now."""
        return self._muted.get(channel, -1e300) > self._clock()

    def unmute(self, channel: str):
        """Hear `channel` again at once (an owner that asks for a stream)."""
        self._muted.pop(channel, None)
