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

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from msg_defs.msg import Heartbeat
from rubber_rig.session import liveness
from rubber_rig.session.liveness import PERIOD, SILENT, OwnerSilence, OwnerWatch  # noqa: F401 - the nodes' names

from . import topics
from .auth import HEARTBEAT
from .draining import create_draining_subscription


def start_heartbeat(node: Node, state: Callable[[], str] = lambda: '', timer: bool = True) -> Callable[[], None]:
    """Beat now and then every PERIOD on the node's relative ``heartbeat`` topic, with `state()` as the state text;
    signed when the node has an ``auth`` (NodeAuth): a forged beat in its name is refused by a Peers that verifies.
    Returns the beat; with ``timer=False`` the node calls it every PERIOD itself (from its one timer: ticks.py).
    """
    pub = node.create_publisher(Heartbeat, topics.HEARTBEAT, topics.HEARTBEAT_QOS)
    auth = getattr(node, 'auth', None)     # signed with the rig's key when the node has one (nodes/auth.py)
    name, pid, count = node.get_fully_qualified_name(), os.getpid(), [0]

    def beat():
        msg = Heartbeat(node=name, pid=pid, count=count[0], state=str(state()))
        msg.header.stamp = node.get_clock().now().to_msg()
        if auth is not None:
            auth.sign(msg, HEARTBEAT)
        pub.publish(msg)
        count[0] += 1
    if timer:
        node.create_timer(PERIOD, beat)
    beat()
    return beat


class Peers(liveness.Peers):
    """liveness.Peers fed by `node`'s subscription to the suite's ``heartbeat`` topic. With `auth` (NodeAuth) only
    beats with a valid signature count: a forged beat must not keep a frozen stream owner alive.
    """

    def __init__(self, node: Node, expected: list[str] | None = None, silent: float = SILENT,
                 clock: Callable[[], float] = time.monotonic, auth=None, polled: bool = False):
        super().__init__(expected, silent, clock)
        self.auth = auth     # NodeAuth: beats without a valid signature are refused (counted in its verifier)
        self._node, self._topic = node, node.resolve_topic_name(topics.HEARTBEAT)
        # polled: the node calls read() from its tick; the beats wake it no more (nodes/draining.py)
        self.subscription = create_draining_subscription(node, Heartbeat, topics.HEARTBEAT, self.on_beat,
                                                         topics.HEARTBEAT_QOS, polled=polled)

    def read(self) -> None:
        """Handle the beats that arrived since the last read (a polled Peers)."""
        self.subscription.drain()

    def on_beat(self, msg: Heartbeat) -> None:
        where = f'{self._topic} (beat of {msg.node})'
        if self.auth is not None and self.auth.refuse(self._node, msg, HEARTBEAT, where):
            return
        super().on_beat(msg)


def annotate_owner_silence(msg: DiagnosticArray, silence: OwnerSilence) -> DiagnosticArray:
    """The driver's /diagnostics ``msg`` with the silent stream owner's lines (session.liveness.OwnerSilence), the
    silent owner said first in its message (at least WARN), where an operator looks (rqt_robot_monitor, Foxglove).
    """
    status, lines = msg.status[0], silence.lines()
    status.values.extend(KeyValue(key=k, value=str(v)) for k, v in lines.items())
    if lines.get('silent_stream_owner'):
        status.message = (f"stream owner {lines['silent_stream_owner']} silent for "
                          f"{lines['silent_stream_owner_for_s']} s (no heartbeat); {status.message}")
        status.level = max(status.level, DiagnosticStatus.WARN)
    return msg
