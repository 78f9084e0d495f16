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
from .active_faults import FaultScenarios
from .active_power import PowerUpScenarios
from .active_stream import StreamScenarios
from .link import Aborted
from .passive import check_offline
from .reference_specimen import MeasureScenarios
from .report import FAIL, NOT_TESTED, Results
from .requirements import REQUIREMENTS


class ConformanceRun(PowerUpScenarios, StreamScenarios, MeasureScenarios, FaultScenarios):
    """One conformance run of the controller on `bus` (any python-can Bus) at sample_rate [Hz] with frame
    `profile`, inside `envelope`. run() returns the Results of every CTRL requirement.
    """

    def scenarios(self) -> tuple:
        """The scenarios in the order they run (each a method marked with the requirements it judges)."""
        every = ((self.s_power_up,) if self.power_up else ()) + (
            self.s_listen, self.s_identify, self.s_stream, self.s_stale, self.s_reference, self.s_hold,
            self.s_reset_moving, self.s_bad_frames, self.s_host_limits, self.s_out_of_limits, self.s_too_fast,
            self.s_host_silence, self.s_wrap)
        return every if self.only is None else tuple(s for s in every if s.__name__ in self.only)

    def run(self) -> Results:
        """Every scenario in order; the offline-checkable requirements from the whole trace at the end.

        A scenario that fails on its own fails the requirements it had not judged, with the reason, and the run
        goes on from rest; only Aborted (the envelope left, or a controller that will not come to rest) ends it.
        """
        if self.simulated is None:
            self._rx.start()
        try:
            for scenario in self.scenarios():
                self.log(f'conformance: {scenario.__doc__.splitlines()[0].rstrip(".")}')
                before = {rid: (r.status, r.measured) for rid, r in self.results.items()}
                try:
                    scenario()
                except Aborted:
                    raise
                except Exception as exc:   # noqa: BLE001 - any failure of one scenario is that scenario's verdict
                    self._scenario_failed(scenario, exc, before)
        except Aborted as exc:
            self.command(CMD_ABORT, 0.0)
            self.log(f'conformance: ABORTED: {exc}')
            self.deviation = self.deviation or str(exc)
        finally:
            self.heartbeat = False
            self._pause(0.1)
            self._stop.set()
            if self._rx.is_alive():
                self._rx.join(timeout=2.0)
        self.merge_host_timing()
        if not self.deviation:
            passive = check_offline(self.trace)
            for rid, r in passive.items():
                if rid.startswith('CTRL'):
                    self.results.put(rid, r.status, r.measured, r.detail)
        why = (f'run aborted: {self.deviation}' if self.deviation else
               f'a short run of {", ".join(sorted(self.only))} only' if self.only is not None else
               'needs the controller switched on during the run (--power-up)')
        return self.results.complete({r.id for r in REQUIREMENTS if r.id.startswith('CTRL')}, why)

    def _scenario_failed(self, scenario, exc: Exception, before: dict):
        """`scenario` raised `exc`: each requirement it judges and had not judged yet fails with the reason (where
        in the scenario, what was raised); then the controller is brought to rest for the next scenario.
        """
        where = traceback.extract_tb(exc.__traceback__)[-1]
        reason = (f'scenario {scenario.__name__} could not complete: {type(exc).__name__}: {exc} (at '
                  f'{Path(where.filename).name}:{where.lineno}); the controller did not do what the scenario '
                  'needs to judge this')
        self.log(f'conformance: {reason}')
        for rid in scenario.requirements:
            r = self.results.get(rid)
            if r is None or (r.status, r.measured) == before.get(rid, (NOT_TESTED, '')):
                self.results.put(rid, FAIL, '', reason)
        self.to_rest(0.0)      # raises Aborted when the controller cannot be brought to rest

    def trace_to_log(self, path):
        """Write every frame of the run, with the times it was judged by, to the raw CAN log `path` (.blf, .asc,
        .log): the offline mode then reads what this run saw.
        """
        with self.lock:
            frames = list(self.trace.frames)
        frames.sort(key=lambda f: f.t)
        with can.Logger(str(path)) as writer:
            for f in frames:
                m = f.msg
                writer.on_message_received(can.Message(
                    timestamp=f.t, arbitration_id=m.arbitration_id, data=m.data, dlc=m.dlc, is_fd=m.is_fd,
                    bitrate_switch=m.bitrate_switch, is_extended_id=m.is_extended_id,
                    is_remote_frame=m.is_remote_frame, is_rx=not f.host, channel=0, check=False))
