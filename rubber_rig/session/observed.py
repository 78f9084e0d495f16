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

"""Who was silent, and who merely looked silent: what a program's result may say about the suite's nodes (ROS-free).

A node that was itself stopped (SIGSTOP, a callback that blocked, a starved process) sees, when it runs again,
every other node's last message as old as its own stall: the rig driver's status, the recorder's status, every
heartbeat. Judged by the age of the last message received, all of them "went silent" at the same moment, and a
result blamed the driver and the recorder for a stall of its own (issue 39). Here:

- :class:`StallWatch` times the node's own executor (``tick`` on every callback): a gap longer than its limit is a
  stall *of this node*; ``since(seen, now)`` is how long nothing came from a peer counting only time this node was
  running to hear it (a peer is silent only if it stays silent after this node resumed).
- :class:`BeatLog` measures a peer's silence from the peer's own heartbeats: consecutive beats (``count`` + k)
  stamped further apart than k beat periods plus the silence limit mean the peer did not beat (its own stall); a
  count that jumped with stamps at the beat period means it beat on and this node did not hear (its own stall, or
  transport), which is no silence of the peer.
- :class:`ProgramWitness` keeps what one program saw and says it in the goal's result: which node stalled (this one,
  for how long), which peers beat on through that stall (resumed), which peers were silent, measured from their
  own heartbeats, and whether they beat again.

Times: ``now`` and ``received`` on this node's monotonic clock [s]; heartbeat stamps on the sender's clock [s]
(only differences of one sender's stamps are used, never compared with this node's clock).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field


class StallWatch:
    """This node's own executor stalls: a gap longer than ``limit`` [s] between two ticks.

    Parameters
    ----------
    limit : float
        [s] a gap between ticks longer than this is a stall (the node's callbacks did not run).
    """

    def __init__(self, limit: float):
        self.limit = float(limit)
        self.last = None
        self.stalls: list[tuple[float, float]] = []     # (start, end) [s, monotonic] of each stall
        self.resumed_at = -math.inf

    def tick(self, now: float) -> tuple[float, float] | None:
        """A callback of the node runs at ``now``; the stall that just ended, if the last tick is too old."""
        stall = None
        if self.last is not None and now - self.last > self.limit:
            stall = (self.last, now)
            self.stalls.append(stall)
            self.resumed_at = now
        if self.last is None or now > self.last:
            self.last = now
        return stall

    def since(self, seen: float, now: float) -> float:
        """[s] without news from a peer last heard at ``seen``, counting only the time since this node last resumed
        (what it could have heard).
        """
        return now - max(seen, self.resumed_at)

    def during(self, start: float) -> list[tuple[float, float]]:
        """The stalls that ended after ``start``."""
        return [s for s in self.stalls if s[1] > start]


@dataclass
class Beat:
    pid: int
    count: int
    stamp: float        # [s] sender's clock
    received: float     # [s] this node's monotonic clock


@dataclass
class Silence:
    """A silence of a peer measured from its own heartbeats: ``duration`` [s] between the beat before and the beat
    that ended it (None: it has not beaten again; ``since`` [s, monotonic] is when it was last heard then).
    """

    node: str
    duration: float
    ended: bool
    received: float     # when the beat that ended it (or the last beat) was received [s, monotonic]


class BeatLog:
    """The heartbeats of the suite's other nodes and their silences, measured from their own beats.

    Parameters
    ----------
    silent : float
        [s] a peer that did not beat for longer than this was silent (heartbeat.SILENT).
    period : float
        [s] the heartbeat period (heartbeat.PERIOD).
    """

    def __init__(self, silent: float, period: float):
        self.silent, self.period = float(silent), float(period)
        self.last: dict[str, Beat] = {}
        self.silences: list[Silence] = []     # ended silences, in the order their ending beats came
        self.continuous: dict[str, float] = {}   # node -> received time of a beat that shows it beat on

    def beat(self, node: str, pid: int, count: int, stamp: float, now: float) -> Silence | None:
        """A heartbeat of ``node`` (``count`` and ``stamp`` [s] as it sent them) received at ``now``; the silence it
        ended, if the beats before it show one.
        """
        prev = self.last.get(node)
        self.last[node] = Beat(int(pid), int(count), float(stamp), float(now))
        if prev is None or prev.pid != pid or count <= prev.count:
            return None                           # first beat, a restart (new pid) or a repeat: nothing to measure
        steps = count - prev.count
        gap = stamp - prev.stamp - (steps - 1) * self.period   # the longest it can have gone without a beat
        if gap > self.silent:
            silence = Silence(node, gap, True, now)
            self.silences.append(silence)
            return silence
        self.continuous[node] = now
        return None

    def quiet(self, now: float, stall: StallWatch) -> dict[str, float]:
        """{node: [s] silent} of the peers not heard for longer than the limit, counting only time this node ran."""
        ages = {n: stall.since(b.received, now) for n, b in self.last.items()}
        return {n: a for n, a in sorted(ages.items()) if a > self.silent}


@dataclass
class ProgramWitness:
    """What one program saw of its own node and of the others; its words for the goal's result.

    ``me``: this node's fully qualified name; ``start``: when the program started [s, monotonic].
    """

    me: str
    start: float
    silent_before: set = field(default_factory=set)      # silent when the program started: not its business
    silent_seen: dict = field(default_factory=dict)      # node -> longest silence [s] (from its own beats, or ongoing)

    def watch(self, beats: BeatLog, stall: StallWatch, now: float) -> dict[str, float]:
        """Note the peers quiet now (returned: {node: s}) and the silences their own beats showed since the start."""
        quiet = beats.quiet(now, stall)
        for name, age in quiet.items():
            if name not in self.silent_before:
                self.silent_seen[name] = max(age, self.silent_seen.get(name, 0.0))
        for s in beats.silences:
            if s.received >= self.start and s.node not in self.silent_before:
                # the beats measure the whole silence; an ongoing measure taken before it ended counted less
                self.silent_seen[s.node] = max(s.duration, self.silent_seen.get(s.node, 0.0))
        self.silent_before &= set(quiet)          # a node silent before the start that beats again is watched again
        return quiet

    def words(self, beats: BeatLog, stall: StallWatch, now: float) -> list[str]:
        """The observations for the goal's result: this node's stalls, the peers that beat on through them, the
        peers that were silent (how long, from their own heartbeats; beating again or not).
        """
        out = []
        stalls = stall.during(self.start)
        if stalls:
            longest = max(b - a for a, b in stalls)
            end = stalls[-1][1]
            n = len(stalls)
            text = (f'{self.me} (this node) stalled for {longest:.1f} s' + (f' ({n} stalls)' if n > 1 else '')
                    + ': its own callbacks did not run, so the rig status, the recorder status and the heartbeats '
                    'it missed then are no silence of theirs')
            on = sorted(n for n, t in beats.continuous.items() if t >= end and n not in self.silent_seen)
            if on:
                text += f'; beat on through it (their own heartbeats show no gap): {", ".join(on)}'
            unheard = sorted(n for n, b in beats.last.items() if b.received < end and n not in self.silent_seen)
            if unheard:
                text += f'; not heard from since: {", ".join(unheard)}'
            out.append(text)
        quiet = beats.quiet(now, stall)
        if self.silent_seen:
            out.append('silent during the program: ' + ', '.join(
                f'{n} up to {a:.1f} s' + (' (still silent)' if n in quiet else ' (beats again)')
                for n, a in sorted(self.silent_seen.items())))
        return out
