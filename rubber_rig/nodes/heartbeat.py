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

"""Liveness of the suite's nodes: every node beats on ``heartbeat`` (msg_defs/Heartbeat) every PERIOD from its
own executor, and a Peers watcher says which expected node has been silent for longer than SILENT.

A beat is sent by a timer of the node's executor, so it stops when anything stops that executor: a callback
that never returns, a thread stuck inside DDS (seen once: element_model deadlocked in Fast DDS discovery, alive
at 0 % CPU, gone from the graph), a stopped process. Process supervision (is the pid there?) sees none of these.
"""
from __future__ import annotations

import os
import time
from typing import Callable

from rclpy.node import Node

from msg_defs.msg import Heartbeat

from . import topics

PERIOD = 0.25        # [s] between beats
# [s] without a beat: the node is called silent (three beats missed; a watcher that checks every 0.1 s names
# it within 0.85 s of its last beat)
SILENT = 0.75


def start_heartbeat(node: Node, state: Callable[[], str] = lambda: '') -> None:
    """Beat every PERIOD on the node's relative ``heartbeat`` topic, with `state()` as the state text."""
    pub = node.create_publisher(Heartbeat, topics.HEARTBEAT, topics.HEARTBEAT_QOS)
    name, pid, count = node.get_fully_qualified_name(), os.getpid(), [0]

    def beat():
        msg = Heartbeat(node=name, pid=pid, count=count[0], state=str(state()))
        msg.header.stamp = node.get_clock().now().to_msg()
        pub.publish(msg)
        count[0] += 1
    node.create_timer(PERIOD, beat)
    beat()


class Peers:
    """Which of the expected nodes (fully qualified names) beat, and which have gone silent.

    A node never heard from is not silent (it may not run in this set-up); one heard from and then silent for
    more than `silent` seconds is, until it beats again (a restarted node is a new pid and says so).
    """

    def __init__(self, node: Node, expected: list[str] | None = None, silent: float = SILENT,
                 clock: Callable[[], float] = time.monotonic):
        self.expected = set(expected or ())
        self.silent_after, self._clock = float(silent), clock
        self.last: dict[str, tuple[float, Heartbeat]] = {}
        self.restarts: dict[str, int] = {}
        node.create_subscription(Heartbeat, topics.HEARTBEAT, self.on_beat, topics.HEARTBEAT_QOS)

    def on_beat(self, msg: Heartbeat) -> None:
        old = self.last.get(msg.node)
        if old is not None and old[1].pid != msg.pid:
            self.restarts[msg.node] = self.restarts.get(msg.node, 0) + 1
        self.last[msg.node] = (self._clock(), msg)

    def now(self) -> float:
        """The time [s] on the clock beats are stamped with."""
        return self._clock()

    def age(self, name: str, since: float | None = None) -> float | None:
        """Seconds since `name` last beat (None: never heard), or since `since` (a time of now()) if that is later."""
        seen = self.last.get(name)
        if seen is None:
            return None
        return self._clock() - (seen[0] if since is None else max(seen[0], since))

    def silent(self, names=None) -> dict[str, float]:
        """{node: seconds silent} of the nodes (default: the expected ones and every node heard from) that beat
        once and then stopped for longer than the silence limit.
        """
        names = set(self.last) | self.expected if names is None else set(names)
        ages = {n: self.age(n) for n in names}
        return {n: a for n, a in sorted(ages.items()) if a is not None and a > self.silent_after}

    def describe(self, names=None) -> str:
        """'' when every node beats, else 'silent: /ns/element_model (1.3 s), ...'."""
        quiet = self.silent(names)
        return ('silent: ' + ', '.join(f'{n} ({a:.1f} s)' for n, a in quiet.items())) if quiet else ''


class OwnerWatch:
    """How long a stream's owner has been silent (rig_driver's owner_timeout judges it): since its last beat, or
    since the grant if that is later. An owner restarted after a kill opens its stream before its first beat has
    arrived; its predecessor's last beat (the same node name) is not its own silence.
    """

    def __init__(self, peers: Peers):
        self.peers = peers
        self._grant, self._since = None, 0.0

    def silent_for(self, grant) -> float | None:
        """Seconds `grant.owner` has been silent (None: never heard, e.g. a client that does not beat)."""
        if grant is not self._grant:          # first seen now: the grant is at most one status period old
            self._grant, self._since = grant, self.peers.now()
        return self.peers.age(grant.owner, since=self._since)
