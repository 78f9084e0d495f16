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

"""One timer per node: its periodic duties (heartbeat, status, diagnostics, peer checks, ...) run from one tick.

Each timer is an entity the node's executor waits on and a wake-up of its own; rclpy rebuilds its wait set on every
wake-up, which costs more CPU than most of the duties themselves (issue 37: about 0.4 ms per wake-up here). A node
hands its duties to :class:`NodeTicks`, which keeps one timer at the shortest period and asks the ROS-free
session.cadence.Cadence, with ``now`` from the node's clock (simulated with use_sim_time), which are due.

``every_tick``: a function run on every tick before the duties (rig_driver's bus poll while it is active), with
the period it needs; the timer then ticks at the shorter of the two periods. ``tick_now``: a tick from an event
that woke the node anyway, which restarts the timer's period (rig_driver's frames: one wake-up per batch, not a
batch's and a timer's). Changing it replaces the timer (rclpy
timers keep their period), so the node still has one.
"""
from __future__ import annotations

from typing import Callable

from rclpy.node import Node

from rubber_rig.session.cadence import Cadence


class NodeTicks:
    """The duties ``duties`` (name -> (period [s], function)) of ``node``, run from one timer."""

    def __init__(self, node: Node, duties: dict[str, tuple[float, Callable[[], object]]]):
        self.node = node
        self.cadence = Cadence({name: period for name, (period, _) in duties.items()})
        self.actions = {name: fn for name, (_, fn) in duties.items()}
        self._every_tick: Callable[[], object] | None = None
        self._timer = None
        self._start(self.cadence.tick_period())

    @property
    def period(self) -> float:
        """The timer's period [s] now."""
        return self._period

    def every_tick(self, fn: Callable[[], object] | None, period: float = 0.0) -> None:
        """Run ``fn`` on every tick, at least every ``period`` [s] (None: no longer)."""
        self._every_tick = fn
        self._start(min(period, self.cadence.tick_period()) if fn is not None else self.cadence.tick_period())

    def tick(self) -> None:
        if self._every_tick is not None:
            self._every_tick()
        for name in self.cadence.due(self.node.get_clock().now().nanoseconds * 1e-9):
            self.actions[name]()

    def tick_now(self) -> None:
        """A tick from an event that woke the node anyway (rig_driver's frames), and the timer's period starts
        again: while such events come more often than the period, the timer never fires, and each of them is the
        only wake-up (the timer still ticks when they stop: a silent bus is the watchdog's to see).
        """
        self.tick()
        if self._timer is not None:
            self._timer.reset()

    def _start(self, period: float) -> None:
        if self._timer is not None:
            if abs(period - self._period) < 1e-12:
                return
            self.node.destroy_timer(self._timer)
        self._period = period
        self._timer = self.node.create_timer(period, self.tick)

    def close(self) -> None:
        if self._timer is not None:
            self.node.destroy_timer(self._timer)
            self._timer = None
