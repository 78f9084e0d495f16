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

"""The online conformance run: drive a controller through the scenarios of the specification with small motion
inside a displacement envelope the operator states, and judge every requirement from what it did.

The host side here is deliberately not the driver: it must send what a driver never would (corrupted, foreign
and stale frames, a setpoint outside the limits, one too fast, silence). Every frame sent and received goes into
one Trace; the requirements a trace alone can show are then judged by the same code as the offline mode
(passive.check_offline). Safety: every measured displacement and applied command is checked against the
envelope as it arrives; a sample outside it, or a tracking error above a third of it, commands ABORT at once and
ends the run (Aborted). Motion is slow (a few mm/s) and at most 80 % of the envelope.
"""
from __future__ import annotations

import traceback
from pathlib import Path

import can

from ..can.protocol import CMD_ABORT
from . import active_faults, active_limits, active_power, active_ramps, active_stream, reference_specimen
from .host_excuse import excuse
from .link import Aborted, ConformanceLink
from .passive import check_offline
from .report import FAIL, NOT_TESTED, Results, Stretch
from .requirements import REQUIREMENTS

#: every scenario in the order a run takes them: functions of the run's ConformanceLink, each marked with the
#: requirements it judges (link.judges); a run without --power-up leaves out the first
SCENARIOS = (active_power.s_power_up, active_stream.s_listen, active_stream.s_identify, active_stream.s_stream,
             active_stream.s_stale, reference_specimen.s_reference, active_ramps.s_hold, active_ramps.s_reset_moving,
             active_faults.s_bad_frames, active_faults.s_host_limits, active_faults.s_out_of_limits,
             active_limits.s_tightened_limits, active_faults.s_too_fast, active_faults.s_host_silence,
             active_faults.s_wrap)


def scenarios_judging(requirements) -> set:
    """The names of the scenarios a short run needs to judge `requirements` (CTRL ids): those that judge one, and
    s_stream for the requirements only the whole trace shows (the power-up scenario always runs in an in-process
    run; the host timeout and rated velocity come from the identity the controller sends at power-up).
    """
    names, judged = set(), set()
    for scenario in SCENARIOS:
        if set(scenario.requirements) & set(requirements):
            names.add(scenario.__name__)
            judged |= set(scenario.requirements)
    if set(requirements) - judged:
        names.add('s_stream')
    return names


class ConformanceRun:
    """One conformance run of the controller on `bus` (any python-can Bus) at sample_rate [Hz] with frame
    `profile`, inside `envelope`. run() returns the Results of every CTRL requirement.

    The run holds the host end (``link``, a ConformanceLink: frames, envelope watch, results) and takes the
    scenarios one after the other, each a function of that link (SCENARIOS; a short run takes those named in
    `only`). The other arguments are the link's.
    """

    def __init__(self, bus: can.BusABC, sample_rate: float, envelope, profile: str = 'packed', log=print,
                 power_up=None, host_timing_files=(), reference=None, ambient=None, only=None, simulated=None):
        self.link = ConformanceLink(bus, sample_rate, envelope, profile, log=log, power_up=power_up,
                                    host_timing_files=host_timing_files, reference=reference, ambient=ambient,
                                    only=only, simulated=simulated)

    # what a report reads of the run: the link's
    results = property(lambda self: self.link.results)
    deviation = property(lambda self: self.link.deviation)
    identity = property(lambda self: self.link.identity)
    host_timing = property(lambda self: self.link.host_timing)
    reference = property(lambda self: self.link.reference)
    ambient = property(lambda self: self.link.ambient)
    trace = property(lambda self: self.link.trace)
    state = property(lambda self: self.link.state)
    faults = property(lambda self: self.link.faults)

    def scenarios(self) -> tuple:
        """The scenarios in the order they run."""
        link = self.link
        every = SCENARIOS if link.power_up else SCENARIOS[1:]
        return every if link.only is None else tuple(s for s in every if s.__name__ in link.only)

    def run(self) -> Results:
        """Every scenario in order; the offline-checkable requirements from the whole trace at the end.

        A scenario that fails on its own fails the requirements it had not judged, with the reason, and the run
        goes on from rest; only Aborted (the envelope left, or a controller that will not come to rest) ends it.
        At the end, a scenario's FAIL that this host's lateness explains is not judged (host_excuse.excuse).
        """
        link = self.link
        origin = link.now()
        link.start()
        try:
            for scenario in self.scenarios():
                link.log(f'conformance: {scenario.__doc__.splitlines()[0].rstrip(".")}')
                before = {rid: (r.status, r.measured) for rid, r in link.results.items()}
                # a FAIL that names no stretch of its own judged the scenario so far (host_excuse)
                started = link.now()
                link.results.stamp = lambda name=scenario.__name__, t0=started: Stretch(t0, link.now(), name)
                try:
                    scenario(link)
                except Aborted:
                    raise
                except Exception as exc:   # noqa: BLE001 - any failure of one scenario is that scenario's verdict
                    self._scenario_failed(scenario, exc, before)
                finally:
                    link.results.stamp = None
        except Aborted as exc:
            link.command(CMD_ABORT, 0.0)
            link.log(f'conformance: ABORTED: {exc}')
            link.deviation = link.deviation or str(exc)
        finally:
            link.stop()
        link.merge_host_timing()
        if not link.deviation:
            passive = check_offline(link.trace)
            for rid, r in passive.items():
                if rid.startswith('CTRL'):
                    link.results.put(rid, r.status, r.measured, r.detail)
        # every source of this host's lateness is in now: a scenario's FAIL it explains is not judged
        excused = excuse(link.results, link.trace.host_late, origin)
        if excused:
            link.log(f'conformance: not judged, this host was late where they failed: {", ".join(excused)}')
        why = (f'run aborted: {link.deviation}' if link.deviation else
               f'a short run of {", ".join(sorted(link.only))} only' if link.only is not None else
               'needs the controller switched on during the run (--power-up)')
        return link.results.complete({r.id for r in REQUIREMENTS if r.id.startswith('CTRL')}, why)

    def _scenario_failed(self, scenario, exc: Exception, before: dict):
        """`scenario` raised `exc`: each requirement it judges and had not judged yet fails with the reason (where
        in the scenario, what was raised); then the controller is brought to rest for the next scenario.
        """
        link = self.link
        where = traceback.extract_tb(exc.__traceback__)[-1]
        reason = (f'scenario {scenario.__name__} could not complete: {type(exc).__name__}: {exc} (at '
                  f'{Path(where.filename).name}:{where.lineno}); the controller did not do what the scenario '
                  'needs to judge this')
        link.log(f'conformance: {reason}')
        for rid in scenario.requirements:
            r = link.results.get(rid)
            if r is None or (r.status, r.measured) == before.get(rid, (NOT_TESTED, '')):
                link.results.put(rid, FAIL, '', reason)
        link.to_rest(0.0)      # raises Aborted when the controller cannot be brought to rest

    def trace_to_log(self, path):
        """Write every frame of the run, with the times it was judged by, to the raw CAN log `path` (.blf, .asc,
        .log): the offline mode then reads what this run saw.
        """
        with self.link.lock:
            frames = list(self.link.trace.frames)
        frames.sort(key=lambda f: f.t)
        with can.Logger(str(path)) as writer:
            for f in frames:
                m = f.msg
                writer.on_message_received(can.Message(
                    timestamp=f.t, arbitration_id=m.arbitration_id, data=m.data, dlc=m.dlc, is_fd=m.is_fd,
                    bitrate_switch=m.bitrate_switch, is_extended_id=m.is_extended_id,
                    is_remote_frame=m.is_remote_frame, is_rx=not f.host, channel=0, check=False))
