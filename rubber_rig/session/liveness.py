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

"""Liveness of peers from their heartbeats, ROS-free: which node beat when, which has gone silent, and how long a
stream's owner has been silent (the rule by which rig_driver takes the stream from a frozen or dead owner).

The beats come from the node's ``heartbeat`` subscription (rubber_rig.nodes.heartbeat) or, on simulated time, from
a scenario (rubber_rig.session.scenario); ``clock`` is the time they are judged on.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

PERIOD = 0.25        # [s] between beats
# [s] without a beat: the node is called silent (three beats missed; a watcher that checks every 0.1 s names
# it within 0.85 s of its last beat)
SILENT = 0.75
#: [s] rig_driver's owner_timeout by default: a stream owner silent this long has lost its stream. Above the
#: longest executor stall a busy computer causes (0.8 s) plus a beat period, so a stalled owner keeps its stream;
#: a dead streaming owner is caught earlier by its queue running short (the driver's stream_timeout)
OWNER_TIMEOUT = 1.5


@dataclass
class Beat:
    """A heartbeat as the owner watch reads it (msg_defs/Heartbeat's node and pid)."""

    node: str
    pid: int


class Peers:
    """Which of the expected nodes (fully qualified names) beat, and which have gone silent.

    A node never heard from is not silent (it may not run in this set-up); one heard from and then silent for
    more than `silent` seconds is, until it beats again (a restarted node is a new pid and says so).
    """

    def __init__(self, expected: list[str] | None = None, silent: float = SILENT,
                 clock: Callable[[], float] = time.monotonic):
        self.expected = set(expected or ())
        self.silent_after, self._clock = float(silent), clock
        self.last: dict[str, tuple[float, object]] = {}   # node -> (when heard, the beat: .node, .pid, ...)
        self.restarts: dict[str, int] = {}

    def on_beat(self, msg) -> None:
        """A beat (msg_defs/Heartbeat, or anything with ``node`` and ``pid``) heard now."""
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

    def lost(self, grant, owner_timeout: float) -> str:
        """Why `grant`'s owner has lost its stream ('' if it has not): it beat and then stayed silent for more than
        owner_timeout [s]. A client that never beats is never judged by its beats (the stream timeout still is).
        """
        if grant is None or not grant.owner:
            return ''
        age = self.silent_for(grant)
        if age is None or age <= owner_timeout:
            return ''
        return f'{grant.owner} silent for {age:.2f} s (no heartbeat; alive but stuck, or gone)'


class OwnerSilence:
    """rig_driver's latest stream owner while it is silent (no beat for SILENT s, at most the owner watch's limit
    ``peers.silent_after``: rig_driver's owner_timeout), whatever ended its stream (the owner watch, the stream
    timeout, the rig running out of setpoints): for /diagnostics, how long, until it beats again (the fault names
    alone do not say who froze).
    """

    def __init__(self, peers: Peers):
        self.peers = peers
        self.owner = ''        # the latest stream owner
        self.silent = ''       # the owner while it is silent
        self._said = None      # (state, faults, silent) of the latest news

    def limit(self) -> float:
        return min(self.peers.silent_after, SILENT)

    def update(self, stream_owner: str, state, faults) -> bool:
        """Note the stream owner of a rig status in ``state`` with ``faults``; True if there is news for /diagnostics
        (a fault, or the owner fell silent or beats again) that should go out now, not at their next period.
        """
        if stream_owner:
            self.owner = stream_owner
        key = (state, faults, self.is_silent())
        if key != self._said:
            self._said = key
            return True
        return False

    def _age(self):
        owner = self.silent or self.owner
        return owner, (self.peers.age(owner) if owner else None)

    def is_silent(self) -> bool:
        _, age = self._age()
        return age is not None and age > self.limit()

    def lines(self) -> dict:
        """The /diagnostics values: ``silent_stream_owner`` and for how long, or that it beats again ({} if nothing
        to say).
        """
        owner, age = self._age()
        if age is None:
            return {}
        if age > self.limit():
            self.silent = owner
            return {'silent_stream_owner': owner, 'silent_stream_owner_for_s': f'{age:.2f}'}
        if self.silent:
            self.silent = ''
            return {'silent_stream_owner': '', 'last_silent_stream_owner': f'{owner} (beats again)'}
        return {}
