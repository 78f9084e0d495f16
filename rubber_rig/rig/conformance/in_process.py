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

"""Conformance runs with the controller in this process: the reference controller (rig/reference/, a second
controller written from docs/protocol.md and the DBC alone) and the simulator (rig/sim/), each with its deliberate
defects. What `rubber-rig conformance --reference` and test_reference_controller / test_conformance_traces run.

The controller is switched on by the run (CTRL-PWR-1). By default the run is on simulated time (link.SimulatedTime):
the controller and the run share one clock, stepped 1 ms at a time, on a simulated CAN bus (can.simbus.BusMedium:
bitrate, arbitration and frame times of the configured bus) that stamps every frame with that clock. Every
requirement, timing included, is then judged on a deterministic trace of the controller, whatever else this host
is doing: a timing verdict is the controller's, never this host's. With wall_clock=True (reference controller only)
it runs in a thread of this process in real time on a python-can virtual bus instead; its late ticks are then this
host's lateness and go into the run's host timing (host_timing), as the simulator's do with --sim.
"""
from __future__ import annotations

import itertools
import os
import sys

import can

from ..config import RigConfig
from ..reference import ReferenceController
from ..sim.controller import SimController
from ..stepped import stepped_medium
from .active import ConformanceRun
from .link import Envelope
from .reference_specimen import Ambient, ReferenceSpring

# what the in-process controllers' rig is declared as when the caller declares nothing: its spring and its ambient
REFERENCE_SPRING = ReferenceSpring(1.0e7, 0.01)     # 10 kN/mm +- 1 %
REFERENCE_AMBIENT = Ambient(23.45, 5.0)             # [degC], [K]
LATE_MIN = 0.001      # [s] a tick the in-process controller takes this late is this host's lateness (half the
#                       2 ms of feedback jitter CTRL-FB-2 allows: its thread shares the interpreter with the run's)
_channels = itertools.count()


class SimulatedTime:
    """The run's clock when it runs on simulated time: the controller in this process is polled in steps of `step`
    [s] (`poll(now)`: read the host's frames, take the ticks due, send what is due - ReferenceController.poll,
    SimController.serve), and every frame that arrived is read by the host in the same step, with its arrival time
    (the bus stamps frames with this clock: can.simbus.BusMedium, conformance.in_process). Nothing of this host's
    scheduling enters the trace: the same controller, seed and run give the same frames at the same times, and a
    timing requirement is never "not judged" for this host's lateness. The controller is silent until power_on()
    (CTRL-PWR-1: the run switches it on once it listens).
    """

    def __init__(self, poll, step: float = 0.001, start: float = 1000.0, powered: bool = False):
        self.poll, self.step, self.t, self.powered = poll, float(step), float(start), bool(powered)

    def power_on(self) -> None:
        self.powered = True


def _rig_config(sample_rate: float, profile: str, sim: dict | None = None) -> RigConfig:
    """The bus (and simulator) of an in-process run: the shipped defaults at sample_rate with frame profile."""
    return RigConfig.from_dict({'sample_rate': sample_rate, 'profile': profile, 'fd': profile != 'classic',
                                'paced': True, 'sim': sim or {}})


def _simulated_buses(cfg: RigConfig, simulated: SimulatedTime) -> tuple:
    """(controller bus, host bus) on one simulated CAN bus whose frames are stamped with the simulated clock."""
    medium = stepped_medium(cfg, lambda: simulated.t)
    return medium.attach('controller'), medium.attach('host')


def _conformance_run(host_bus, sample_rate, envelope, profile, reference, ambient, only, log, simulated):
    return ConformanceRun(host_bus, sample_rate, envelope or Envelope(-1e-3, 1e-3), profile, log=log,
                          power_up=simulated.power_on if simulated else None, reference=reference, ambient=ambient,
                          only=None if only is None else set(only) | {'s_power_up'}, simulated=simulated)


def run_against_reference(defects=(), sample_rate: float = 1000.0, envelope: Envelope = None,
                          profile: str = 'packed', reference: ReferenceSpring = REFERENCE_SPRING,
                          ambient: Ambient = REFERENCE_AMBIENT, only=None, log=lambda text: None,
                          wall_clock: bool = False):
    """One conformance run against a ReferenceController with `defects` whose spring and temperature are
    `reference` and `ambient` (declared to the run as the same). only: scenario names for a short run (the power-up
    scenario always runs). wall_clock: run the controller in a thread in real time instead of on simulated time.
    Returns (ConformanceRun, Results).
    """
    simulated = None if wall_clock else SimulatedTime(None, 1.0 / sample_rate)
    if wall_clock:
        channel = f'rubber_rig_reference_{os.getpid()}_{next(_channels)}'
        ctrl_bus = can.Bus(interface='virtual', channel=channel, receive_own_messages=False)
        host_bus = can.Bus(interface='virtual', channel=channel, receive_own_messages=False)
    else:
        ctrl_bus, host_bus = _simulated_buses(_rig_config(sample_rate, profile), simulated)
    ctrl = ReferenceController(ctrl_bus, sample_rate, profile, defects,
                               stiffness=reference.stiffness if reference else 1.0e7,
                               ambient=ambient.temperature if ambient else 23.45)
    interval = sys.getswitchinterval()
    try:
        run = _conformance_run(host_bus, sample_rate, envelope, profile, reference, ambient, only, log, simulated)
        if simulated is not None:
            simulated.poll = ctrl.poll
        else:
            run.link.power_up = lambda: ctrl.start(late=run.host_timing.add, late_min=LATE_MIN)
            # two threads of one interpreter share the GIL: a short switch interval keeps the ticks on time
            sys.setswitchinterval(min(interval, 5e-4))
        results = run.run()
    finally:
        ctrl.stop()
        sys.setswitchinterval(interval)
        host_bus.shutdown()
        ctrl_bus.shutdown()
    return run, results


def run_against_simulator(defects=(), sample_rate: float = 1000.0, envelope: Envelope = None,
                          profile: str = 'packed', reference: ReferenceSpring = REFERENCE_SPRING,
                          ambient: Ambient = REFERENCE_AMBIENT, only=None, log=lambda text: None):
    """One conformance run on simulated time against the simulator (SimController, paced) with its deliberate
    `defects` (conformance.defects.DEFECTS), its specimen the linear spring `reference` at the temperature
    `ambient`, both declared to the run. only: as run_against_reference. Returns (ConformanceRun, Results).
    """
    sim = {'defects': list(defects)}
    if reference is not None:
        sim['specimen'] = {'model': 'linear', 'stiffness': reference.stiffness, 'damping': 0.0}
    if ambient is not None:
        sim['temperature'] = ambient.temperature
    cfg = _rig_config(sample_rate, profile, sim)
    simulated = SimulatedTime(None, 1.0 / sample_rate)
    ctrl_bus, host_bus = _simulated_buses(cfg, simulated)
    ctrl = SimController(ctrl_bus, cfg.sample_rate, cfg.sim, paced=True, profile=cfg.frame_profile,
                         clock=lambda: simulated.t)
    simulated.poll = ctrl.serve
    try:
        run = _conformance_run(host_bus, sample_rate, envelope, profile, reference, ambient, only, log, simulated)
        results = run.run()
    finally:
        host_bus.shutdown()
        ctrl_bus.shutdown()
    return run, results
