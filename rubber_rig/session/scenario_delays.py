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

"""The delays a scenario (session.scenario) injects: a component that misses its wake-ups (Stall), a topic whose
messages arrive late (Link).

A busy computer stalls an executor 0.3-0.8 s, and it delays a message on its way (the publisher's executor, DDS,
the subscriber's queue): a message published while a delay window is open reaches its subscriber's inbox that much
later, in order (a topic never overtakes itself). Time is the scenario's: nothing here reads a clock.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

#: the topics a scenario can delay
PATHS = ('samples', 'setpoints')


@dataclass
class Window:
    """From `at` for `duration` [s] on the scenario clock (inf: never ending)."""

    at: float
    duration: float

    def covers(self, t: float) -> bool:
        return self.at <= t < self.at + self.duration


@dataclass
class Stall(Window):
    """`component` misses its wake-ups from `at` for `duration` [s] on the scenario clock (inf: never again)."""

    component: str = ''


@dataclass
class Delay(Window):
    """Messages published from `at` [s after the program's start] for `duration` [s] arrive `seconds` [s] late."""

    seconds: float = 0.0


class Link:
    """One topic's messages on their way: ``publish`` at a time, ``arrived`` up to a time, first in first out."""

    def __init__(self):
        self.delays: list[Delay] = []
        self._queue: deque = deque()      # (arrival time [s], message)

    def delay(self, seconds: float, at: float = 0.0, duration: float = math.inf) -> None:
        self.delays.append(Delay(float(at), float(duration), seconds=float(seconds)))

    def publish(self, message, now: float, since_start=None) -> None:
        """`message` published at `now` [s]; since_start [s]: the program time the delay windows are judged on
        (None before a program started: no delay).
        """
        late = max((d.seconds for d in self.delays if since_start is not None and d.covers(since_start)),
                   default=0.0)
        arrival = now + late
        if self._queue and self._queue[-1][0] > arrival:
            arrival = self._queue[-1][0]        # behind a message delayed more: a topic keeps its order
        self._queue.append((arrival, message))

    def arrived(self, now: float):
        """The messages that have arrived by `now` [s], oldest first (they leave the link)."""
        while self._queue and self._queue[0][0] <= now:
            yield self._queue.popleft()[1]

    def __len__(self) -> int:
        return len(self._queue)
