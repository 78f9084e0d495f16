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

"""The excitation's rules on when a program may start and when it must stop, ROS-free, on an injected clock.

The excitation node (rubber_rig.nodes.excitation_node) converts what it receives into plain values, tells a
:class:`ProgramWatch` when it heard what (``now``: its node clock [s]) and asks it; the scenario harness
(rubber_rig.session.scenario) takes the same decisions on the rig status and the detector events through
:func:`why_rig_stopped` and :func:`detector_action`. Every answer is '' (go on) or the reason in words, which is
what a refused goal or an ended program says.

- Start (:meth:`ProgramWatch.why_not_start`): a rig status at most ``3 status_timeout`` old (a latched status
  after a restart may be a little older than the period), in a state that takes a stream (idle, running,
  holding), a stream nobody else owns, no program running, our topics matched by DDS (``links``: the node's
  verdict on the graph, :func:`links_verdict`), and the recording ready (``recording``).
- A goal that arrives right after a launch waits (:meth:`ProgramWatch.statuses_fresh`) until the rig status is
  at most ``status_timeout`` old, the recorder's is fresh and the links are ready, at most ``start_timeout``.
- Stop (:meth:`ProgramWatch.why_stop`): a program held longer than ``hold_timeout``; while it streams, the recorder
  gone (``recorder``: RecorderWatch.why_stop) or the driver silent (neither a status nor a sample batch) for longer
  than ``status_timeout``, counted only while this node ran (observed.StallWatch: a stall of its own is not the
  driver's silence).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, Optional

from ..excitation.detectors import strongest
from .observed import StallWatch

#: the rig states a program can start in (the driver's state names, rig.can.protocol.STATES)
READY_STATES = ('idle', 'running', 'holding')
#: a rig status older than this many status_timeout refuses a start (it is latched: one from before a short
#: interruption of the status stream must not refuse a goal, one from a driver gone for seconds must)
START_STATUS_AGE = 3.0


@dataclass
class RigView:
    """What the excitation needs of a rig status (msg_defs/RigStatus, or the core driver's DriverStatus).

    state: the driver's state name ('idle', 'running', 'holding', 'ramping_down', 'fault', 'unconfigured');
    faulted: a fault is latched (state fault or fault bits set); fault_messages: the faults in words (newest last);
    stream_owner: who owns the stream ('' none); stream_id: the open stream (0 none); last_event: the driver's latest
    transition in words.
    """

    state: str
    faulted: bool = False
    fault_messages: list = field(default_factory=list)
    stream_owner: str = ''
    stream_id: int = 0
    last_event: str = ''


@dataclass
class DetectorAction:
    """What the excitation does about a batch of detector events: ``kind`` 'end' (the program ends with ``reason``,
    a success for an end-of-test trigger) or 'hold' (held at the block mean; ``failed`` is the reason to end it if
    the hold cannot be taken).
    """

    kind: str
    reason: str
    success: bool = False
    detector: str = ''
    message: str = ''

    def failed(self, why: str) -> str:
        """The reason a program ends when the hold this action asked for failed for ``why``."""
        return f'detector {self.detector} asked for a hold, which failed ({why}): {self.message}'


def detector_action(events, held: bool) -> Optional[DetectorAction]:
    """The strongest action among detector ``events`` (excitation.detectors.Event) for a program that is ``held`` or
    not: end (a success when a cycle_count or elapsed_time trigger ends the test), hold (if not held already), or
    None (record and warn only: the events are published, nothing else happens).
    """
    if not events:
        return None
    top = strongest(events)
    if top.action == 'end':
        return DetectorAction('end', f'ended by detector: {top.message}', top.kind in ('cycle_count', 'elapsed_time'),
                              top.detector, top.message)
    if top.action == 'hold' and not held:
        return DetectorAction('hold', f'detector {top.detector}', False, top.detector, top.message)
    return None


def why_rig_stopped(rig: RigView, stream_id: int, ending: bool) -> str:
    """Why the program on stream ``stream_id`` ended on the rig's side ('' if it did not): a latched fault, or the
    driver took the stream away (rig_driver/abort, deactivate, a limit change) while the program had not ended
    itself (``ending``: its last setpoint is streamed).
    """
    if rig.faulted:
        return 'rig fault: ' + '; '.join(rig.fault_messages)
    if rig.stream_id != stream_id and not ending:
        return f'the rig stopped the program: {rig.last_event or rig.state}'
    return ''


def links_verdict(endpoints: Iterable[tuple[str, int, int]], acked: bool) -> str:
    """'' once every (what, matched, known) endpoint of the node is matched with every endpoint the graph shows on its
    topic (at least one), and the driver acknowledged what was sent before (``acked``); else what it waits for.

    Right after a launch or a driver restart the status can arrive before DDS has matched the samples and setpoint
    topics: a stream opened then would run dry (no samples pace it) or send to nobody. A reliable reader delivers
    in order: batches of an earlier stream a broken link lost are repaired first, so a stream opened before they
    are acknowledged would reach the driver late and run dry.
    """
    for what, matched, known in endpoints:
        if matched < max(known, 1):
            return f'waiting for discovery: our {what} is matched with {matched} of {max(known, 1)} endpoints'
    if not acked:
        return 'waiting for rig_driver to acknowledge the setpoints sent before (a network link came back?)'
    return ''


class ProgramWatch:
    """The excitation's start and stop rules on its node clock (module doc).

    Parameters
    ----------
    status_timeout : float
        [s] neither a rig status nor a sample batch for this long ends a running program (the driver is gone).
    hold_timeout : float
        [s] a program held this long without a resume ends.
    start_timeout : float
        [s] a goal waits at most this long for fresh statuses and matched topics.
    stall : StallWatch
        This node's own stalls (shared with the peer and recorder watches): silences count only while it ran.
    driver : str
        The rig driver's name, for the words.
    """

    def __init__(self, status_timeout: float, hold_timeout: float, start_timeout: float, stall: StallWatch,
                 driver: str = 'rig_driver'):
        self.status_timeout, self.hold_timeout = float(status_timeout), float(hold_timeout)
        self.start_timeout, self.stall, self.driver = float(start_timeout), stall, driver
        self.rig: Optional[RigView] = None
        self.rig_heard = -math.inf       # [s] the latest rig status
        self.driver_heard = -math.inf    # [s] the latest rig status or sample batch: the driver is alive
        self.held_at: Optional[float] = None

    # -- what the node heard ---------------------------------------------------------------------------------
    def on_rig_status(self, rig: RigView, now: float) -> None:
        self.rig, self.rig_heard = rig, now
        self.driver_heard = max(self.driver_heard, now)

    def on_samples(self, now: float) -> None:
        """A sample batch (signed): the driver is alive as much as its status says (one late status message - DDS can
        hold a topic back for a second when a subscriber process dies - must not stop a running program).
        """
        self.driver_heard = max(self.driver_heard, now)

    def on_hold(self, now: float) -> None:
        self.held_at = now

    # -- starting ---------------------------------------------------------------------------------------------
    def rig_age(self, now: float) -> float:
        return now - self.rig_heard

    def why_not_start(self, now: float, me: str, busy: bool, links: str = '', recording: str = '') -> str:
        """'' when a program can start now, else why not. ``me``: this node's name (its own stream is no other's);
        ``busy``: a program runs or a stream is being opened; ``links``: :func:`links_verdict`; ``recording``: the
        recorder watch's verdict (RecorderWatch.why_not_start).
        """
        rig = self.rig
        if rig is None:
            return "no rig status received on 'status' yet (is rig_driver active?)"
        age = self.rig_age(now)
        if age > self.status_timeout * START_STATUS_AGE:
            return f'the rig status is {age:.1f} s old (is rig_driver running?)'
        if rig.state not in READY_STATES:
            why = '; '.join(rig.fault_messages[-2:])
            return f'rig is {rig.state}' + (f': {why} (rig_driver/reset to acknowledge)' if why else '')
        if rig.stream_owner and rig.stream_owner != me:
            return f'the rig is streaming for {rig.stream_owner}'
        if busy:
            return 'a program is already running'
        return links or recording

    def statuses_fresh(self, now: float, recording_fresh: bool, links: str) -> bool:
        """The rig status (at most status_timeout old), the recorder's (``recording_fresh``) and the topics
        (``links`` == '') are ready to judge a goal.
        """
        return self.rig is not None and self.rig_age(now) <= self.status_timeout and recording_fresh and not links

    def start_wait_over(self, since: float, now: float) -> bool:
        """A goal that arrived at ``since`` has waited start_timeout for fresh statuses by ``now``: judge it now."""
        return now - since >= self.start_timeout

    # -- stopping ---------------------------------------------------------------------------------------------
    def driver_silent(self, now: float) -> float:
        """[s] since the driver was last heard, counting only the time this node ran."""
        return self.stall.since(self.driver_heard, now)

    def why_stop(self, now: float, held: bool, streaming: bool, recorder: str = '') -> str:
        """Why the running program must stop now ('' if it runs on): ``held`` for longer than hold_timeout; while
        ``streaming``, the recorder's verdict ``recorder`` (RecorderWatch.why_stop) or the driver silent for longer
        than status_timeout.
        """
        if held:
            if self.held_at is not None and now - self.held_at > self.hold_timeout:
                return f'held for {self.hold_timeout:g} s without a resume (hold_timeout): ramp to rest'
            return ''
        if not streaming:
            return ''
        if recorder:
            return recorder
        silent = self.driver_silent(now)
        if silent > self.status_timeout:
            return (f'{self.driver} silent for {silent:.1f} s (no status, no samples): the rig controller ramps '
                    'to rest on its own host watchdog')
        return ''


class Throttle:
    """At most one action every ``period`` [s]: ``due(now)`` is true for the first call and then once ``period`` has
    passed since the last true (the goal's feedback, every feedback_period).
    """

    def __init__(self, period: float):
        self.period, self.last = float(period), -math.inf

    def due(self, now: float) -> bool:
        if now - self.last >= self.period:
            self.last = now
            return True
        return False
