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

"""What the excitation says about a program besides its setpoints, ROS-free, on an injected clock: which of the
suite's nodes went silent (from their own heartbeats, observed.BeatLog), whether this node stalled itself
(observed.StallWatch), whether the detectors were blind, and the words and level of its /diagnostics and of the
goal's result.

The node feeds every signed heartbeat (:meth:`PeerWatch.beat`) and asks :meth:`PeerWatch.watch` every 0.1 s what
changed; :func:`program_diagnosis` composes the diagnostics, :func:`result_message` the result's message.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from .liveness import PERIOD, SILENT
from .observed import BeatLog, ProgramWitness, StallWatch

STALL_SHOWN = 10.0   # [s] /diagnostics says this node stalled for this long after the stall


@dataclass
class PeerNews:
    """What :meth:`PeerWatch.watch` found: this node's stall that just ended ((start, end) [s] or None), the peers that
    fell silent ({node: s}) and those that beat again, and whether the set of silent peers changed.
    """

    stall: Optional[tuple] = None
    silent: dict = field(default_factory=dict)
    beating_again: list = field(default_factory=list)
    changed: bool = False


class PeerWatch:
    """The suite's other nodes as the excitation ``me`` hears their heartbeats, and its own stalls.

    Parameters
    ----------
    me : str
        This node's fully qualified name (its own beats are not a peer's).
    silent : float
        [s] a peer without a beat for this long is silent; a gap this long between this node's own callbacks is a
        stall of its own (liveness.SILENT).
    period : float
        [s] the heartbeat period (liveness.PERIOD).
    """

    def __init__(self, me: str, silent: float = SILENT, period: float = PERIOD):
        self.me = me
        self.stall = StallWatch(silent)
        self.beats = BeatLog(silent, period)
        self.witness = ProgramWitness(me, 0.0)
        self.silent_now: dict[str, float] = {}     # as the latest watch() saw it

    @property
    def silent_seen(self) -> dict:
        """Node -> longest silence [s] seen during the running (or last) program."""
        return self.witness.silent_seen

    def beat(self, node: str, pid: int, count: int, stamp: float, now: float) -> None:
        """A (signed) heartbeat of ``node`` received at ``now`` [s] (``stamp``: its sender's clock)."""
        self.stall.tick(now)
        if node != self.me:
            self.beats.beat(node, pid, count, stamp, now)

    def start_program(self, now: float) -> None:
        """A program starts: silences that began before it (a node restarted just before) are not its own."""
        self.witness = ProgramWitness(self.me, now, silent_before=set(self.silent_now))

    def watch(self, now: float, running: bool) -> PeerNews:
        """The peers silent now (while ``running``, remembered for the program's result) and what changed."""
        news = PeerNews(stall=self.stall.tick(now))
        quiet = self.witness.watch(self.beats, self.stall, now) if running else self.beats.quiet(now, self.stall)
        news.silent = {name: age for name, age in quiet.items() if name not in self.silent_now}
        news.beating_again = sorted(set(self.silent_now) - set(quiet))
        news.changed = set(quiet) != set(self.silent_now)
        self.silent_now = quiet
        return news

    def stalled(self, now: float) -> str:
        """This node's latest stall if it ended less than STALL_SHOWN ago, in words (an operator must not look for its
        cause in the nodes it did not hear meanwhile), else ''.
        """
        stalls = self.stall.stalls
        if stalls and now - stalls[-1][1] < STALL_SHOWN:
            return f'this node stalled for {stalls[-1][1] - stalls[-1][0]:.1f} s (its callbacks did not run)'
        return ''

    def words(self, now: float) -> list:
        """The running (or last) program's observations for its result (observed.ProgramWitness.words)."""
        return self.witness.words(self.beats, self.stall, now)

    def heard(self, node: str) -> Optional[float]:
        """[s] when ``node``'s latest beat was received (None: never)."""
        beat = self.beats.last.get(node) if node else None
        return beat.received if beat is not None else None


def blind_detectors(session, sample_rate: float) -> str:
    """Why the cycle detectors of ``session`` (a ProgramSession, or None) cannot trip ('' when they judge cycles as
    they come): no cycle metrics for a while of a periodic block, or the detectors' own blindness.
    """
    if session is None:
        return ''
    since = session.detectors_blind(sample_rate)
    why = [f'no cycle_metrics from element_model for {since:.1f} s of a periodic block (is it running?)'
           if since else '', session.monitor.blind if session.monitor is not None else '']
    return '; '.join(w for w in why if w)


@dataclass
class Diagnosis:
    """The excitation's /diagnostics: ``warn`` (else OK), the ``message`` and the key-value lines."""

    warn: bool
    message: str
    values: dict


def program_diagnosis(state: str, program: str, events: list, blind: str, lost: str, silent: dict,
                      stalled: str) -> Diagnosis:
    """/diagnostics of the excitation in program state ``state`` running ``program`` ('' none): WARN for a detector
    event that did more than record (``events``: the program's, each with its action and message), blind detectors,
    a lost recording, silent peers ({node: s}) or a recent stall of its own; the message says the first of them.
    """
    silent_text = ', '.join(f'{n} ({a:.1f} s)' for n, a in silent.items())
    last_event = events[-1] if events else None
    acted = last_event is not None and last_event.action != 'record'
    values = {'state': state, 'program': program, 'detector_events': len(events),
              'last_event': last_event.message if last_event is not None else '',
              'detectors_blind': blind, 'recording_lost': lost, 'nodes_silent': silent_text, 'stalled': stalled}
    reasons = [stalled, f'nodes silent: {silent_text}' if silent_text else '',
               f'detectors blind: {blind}' if blind else '', lost, last_event.message if acted else '']
    return Diagnosis(acted or any(reasons), next((x for x in reasons if x), f'program {state}'), values)


def result_message(message: str, blind: str = '', recording: str = '', lost: str = '', words=()) -> str:
    """The goal's result ``message`` with what else happened: blind detectors, the recording's words (``recording``;
    without them the loss the program saw, ``lost``), and the peer watch's ``words``.
    """
    if blind:
        message += f' (detectors were blind: {blind})'
    if recording or lost:
        message += f' ({recording or lost})'
    for w in words:
        message += f' ({w})'
    return message
