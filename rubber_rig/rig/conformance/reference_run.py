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

"""A conformance run against the reference controller (rig/reference/) in this process, on a python-can virtual
bus of its own: what `rubber-rig conformance --reference` and test_reference_controller run.

The controller is switched on by the run (CTRL-PWR-1) and runs in a thread of this process; its late ticks are
this host's lateness and go into the run's host timing (host_timing), as the simulator's do with --sim.
"""
from __future__ import annotations

import itertools
import os
import sys

import can

from ..reference import ReferenceController
from .active import ConformanceRun
from .link import Envelope
from .reference_specimen import Ambient, ReferenceSpring

# what the reference controller's rig is declared as when the caller declares nothing: its spring and its ambient
REFERENCE_SPRING = ReferenceSpring(1.0e7, 0.01)     # 10 kN/mm +- 1 %
REFERENCE_AMBIENT = Ambient(23.45, 5.0)             # [degC], [K]
LATE_MIN = 0.001      # [s] a tick the in-process controller takes this late is this host's lateness (half the
#                       2 ms of feedback jitter CTRL-FB-2 allows: its thread shares the interpreter with the run's)
_channels = itertools.count()


def run_against_reference(defects=(), sample_rate: float = 1000.0, envelope: Envelope = None,
                          profile: str = 'packed', reference: ReferenceSpring = REFERENCE_SPRING,
                          ambient: Ambient = REFERENCE_AMBIENT, only=None, log=lambda text: None):
    """One conformance run against a ReferenceController with `defects` whose spring and temperature are
    `reference` and `ambient` (declared to the run as the same). only: scenario names for a short run (the power-up
    scenario always runs). Returns (ConformanceRun, Results).
    """
    envelope = envelope or Envelope(-1e-3, 1e-3)
    channel = f'rubber_rig_reference_{os.getpid()}_{next(_channels)}'
    ctrl_bus = can.Bus(interface='virtual', channel=channel, receive_own_messages=False)
    host_bus = can.Bus(interface='virtual', channel=channel, receive_own_messages=False)
    box = {}
    # two threads of one interpreter share the GIL: a short switch interval keeps the controller's ticks on time
    interval = sys.getswitchinterval()
    sys.setswitchinterval(min(interval, 5e-4))
    try:
        run = ConformanceRun(host_bus, sample_rate, envelope, profile, log=log, power_up=lambda: box['c'].start(
            late=run.host_timing.add, late_min=LATE_MIN), reference=reference, ambient=ambient,
            only=None if only is None else set(only) | {'s_power_up'})
        box['c'] = ReferenceController(ctrl_bus, sample_rate, profile, defects,
                                       stiffness=reference.stiffness if reference else 1.0e7,
                                       ambient=ambient.temperature if ambient else 23.45)
        results = run.run()
    finally:
        if 'c' in box:
            box['c'].stop()
        sys.setswitchinterval(interval)
        host_bus.shutdown()
        ctrl_bus.shutdown()
    return run, results
