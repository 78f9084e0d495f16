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

"""The host's watch over the controller's periodic frames: the driver never trusts silence it has not heard.

Every periodic frame the host relies on (ControllerHeartbeat, ControllerStatus and, where the configuration
requires an identified controller, ControllerIdentity) has a silence limit. The watch is armed when the
controller is first heard at all (any of its frames: it is connected), not when the frame itself is first heard,
so a controller that never sends one of them is silent from its first word on, and faults within that frame's
limit. Before every one of them has been received within its limit no stream may open.

Time is an input: `now` is the caller's clock [s] (paced: wall-clock silence) and `sample` the feedback position
[samples] (as fast as possible there is no wall time: silence is counted in samples of feedback received).
Nothing here reads a clock, so the decisions are tested on simulated time (test_heartbeat_watch).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .protocol import cycle_time

# the frames watched, in the order their silence is reported (the heartbeat is the one a fault names first)
WATCHED = ('ControllerHeartbeat', 'ControllerStatus', 'ControllerIdentity')
GAP_FACTOR = 2.0     # a periodic frame may be one period late (the conformance GAP_FACTOR) before it is silence


def silence_limits(watchdog_timeout: float, require_identity: bool = True) -> dict:
    """{frame name: silence limit [s]}: watchdog_timeout for the heartbeat (the host's stated watchdog), for the
    others the larger of it and GAP_FACTOR of their DBC cycle time (status 10 ms -> watchdog_timeout, identity
    1 s -> 2 s). Without require_identity the identity is not watched.
    """
    limits = {'ControllerHeartbeat': float(watchdog_timeout)}
    for name in WATCHED[1:]:
        if name == 'ControllerIdentity' and not require_identity:
            continue
        limits[name] = max(float(watchdog_timeout), GAP_FACTOR * cycle_time(name))
    return limits


@dataclass
class _Watch:
    """One frame: when it was last heard (clock [s], feedback sample) and when its silence was last armed."""

    heard_t: float = -math.inf
    heard_sample: float | None = None
    armed_t: float = -math.inf
    armed_sample: float | None = None
    count: int = 0


class ControllerLiveness:
    """Silence of the controller's periodic frames, judged by clock time (paced) or by feedback samples.

    limits: {frame name: silence limit [s]} (silence_limits); fs: sample rate [Hz]; paced: judge by `now`
    (True) or by `sample` (False).
    """

    def __init__(self, limits: dict, fs: float, paced: bool):
        self.limits, self.fs, self.paced = dict(limits), float(fs), bool(paced)
        self.watch = {name: _Watch() for name in self.limits}
        self.connected_at = None         # clock time the controller was first heard, or None

    # ---- what arrives
    def connected(self, now: float, sample) -> None:
        """Any controller frame arrived: from the first one on, every watched frame is owed."""
        if self.connected_at is None:
            self.connected_at = now
            self.rearm(now, sample)

    def heard(self, name: str, now: float, sample) -> None:
        """Frame `name` arrived at clock time now [s], with the feedback at `sample` (None: no feedback yet)."""
        self.connected(now, sample)
        w = self.watch.get(name)
        if w is not None:
            w.heard_t, w.heard_sample = now, sample
            w.count += 1

    def rearm(self, now: float, sample) -> None:
        """Judge every frame's silence afresh from now (connection, or faults acknowledged by a reset)."""
        for w in self.watch.values():
            w.armed_t, w.armed_sample = now, sample

    def shift(self, late: float) -> None:
        """This host was not scheduled for `late` [s]: that time is nobody's silence."""
        for w in self.watch.values():
            w.heard_t += late
            w.armed_t += late

    def jumped(self, sequence: int) -> None:
        """An idle rig started a stream at `sequence`: the samples skipped to it did not pass."""
        for w in self.watch.values():
            for attr in ('heard_sample', 'armed_sample'):
                if getattr(w, attr) is None or getattr(w, attr) < sequence:
                    setattr(w, attr, sequence)

    # ---- judgements
    def _settle(self, sample) -> None:
        """Counted in samples: a mark set before any feedback arrived (None) counts from the first sample."""
        if self.paced or sample is None:
            return
        for w in self.watch.values():
            if w.heard_sample is None and w.count:
                w.heard_sample = sample
            if w.armed_sample is None and self.connected_at is not None:
                w.armed_sample = sample

    def _since(self, w: _Watch, now: float, sample, heard_only: bool) -> float:
        """Silence [s] of one frame since it was heard (heard_only) or since it was heard or armed."""
        if self.paced:
            return now - (w.heard_t if heard_only else max(w.heard_t, w.armed_t))
        if heard_only and not w.count:
            return math.inf
        if sample is None:
            return 0.0                   # no feedback yet: no sample has passed in silence
        marks = [m for m in (w.heard_sample, None if heard_only else w.armed_sample) if m is not None]
        return (sample - max(marks)) / self.fs if marks else 0.0

    def silent(self, now: float, sample):
        """(frame name, silence [s], heard before) of the first watched frame silent beyond its limit since it
        was heard or the watch was armed, or None. Nothing is owed before the controller was heard at all.
        """
        if self.connected_at is None:
            return None
        self._settle(sample)
        for name, w in self.watch.items():
            quiet = self._since(w, now, sample, heard_only=False)
            if quiet > self.limits[name]:
                return name, quiet, w.count > 0
        return None

    def why_not_heard(self, now: float, sample) -> str:
        """'' when every watched frame has been received within its limit, else which one was not."""
        self._settle(sample)
        for name, w in self.watch.items():
            limit = self.limits[name]
            if not w.count:
                return (f'no {name} received from the controller yet (expected every '
                        f'{cycle_time(name) * 1e3:g} ms): no stream before it is heard')
            quiet = self._since(w, now, sample, heard_only=True)
            if quiet > limit:
                return (f'{name} last received {quiet:.3f} s ago (silence limit {limit:g} s): no stream to a '
                        'controller not heard')
        return ''
