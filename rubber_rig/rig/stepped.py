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

"""SteppedRig: the simulated controller and the host's RigDriver on one simulated CAN segment, on a simulated
clock that only the caller advances. The paced rig of ``open_rig`` runs its controller in a thread on the wall
clock, so a test of its timing is a test of how busy the computer is; here each ``poll()`` moves time on by one
step, the controller serves what is due (``SimController.serve``) and the driver polls once: the same frames,
samples and faults on any computer, as fast as Python goes. rubber_rig.session.scenario builds on it.
"""
from __future__ import annotations

import weakref

from .can.driver import RigDriver
from .can.simbus import BusMedium
from .config import RigConfig
from .sim.controller import SimController


def stepped_medium(cfg: RigConfig, clock) -> BusMedium:
    """The CAN segment of `cfg` (bitrate, data bitrate, FD, transmit queue) on a simulated clock only the caller
    advances: no thread, and frames stamped with the simulated time itself, so the same run gives the same stamps.
    """
    return BusMedium(cfg.bitrate, cfg.data_bitrate, cfg.fd, tx_queue=cfg.tx_queue, clock=clock, threaded=False,
                     time_offset=0.0)


class SteppedRig:
    """A paced simulated rig (RigConfig or settings over the defaults) whose time is ``now`` [s]; ``step`` [s]
    the time one ``poll()`` lets pass (rig_driver's poll period by default 1 ms here).

    embedded: the controller stands for rig_driver's embedded simulator (a thread of the driver's process: the
    time it misses its deadlines is the host's, and the driver excuses it); by default it stands for a real
    controller on its own CPU, whose silence faults the rig.
    """

    def __init__(self, config=None, step: float = 0.001, start: float = 100.0, embedded: bool = False):
        cfg = config if isinstance(config, RigConfig) else RigConfig.from_dict({**(config or {}), 'paced': True})
        self.cfg, self.step, self.now = cfg, float(step), float(start)
        medium = stepped_medium(cfg, self.clock)
        controller_bus, host_bus = medium.attach('controller'), medium.attach('host')
        self.controller = SimController(controller_bus, cfg.sample_rate, cfg.sim, paced=True,
                                        profile=cfg.frame_profile, clock=self.clock)
        self.driver = RigDriver(host_bus, cfg, clock=self.clock)
        if embedded:
            self.driver.supervisor.host_lateness = self.controller.lateness.lag
        self.driver.measured_load = medium.load
        # the buses have no thread and no socket: they are shut down with the rig, whenever it is collected
        self.close = weakref.finalize(self, _shut_down, controller_bus, host_bus)

    def clock(self) -> float:
        return self.now

    def advance(self, dt: float = None, serve: bool = True) -> None:
        """Let `dt` [s] (default one step) pass; the controller serves what is due (unless it is stalled)."""
        self.now += self.step if dt is None else dt
        if serve:
            self.controller.serve(self.now)

    def poll(self):
        """One step of time, then the driver's poll: the next SampleBlock, or None."""
        self.advance()
        return self.driver.poll()

    def wait_ready(self, timeout: float = 5.0) -> bool:
        """Step until the driver would grant a stream (at most `timeout` [s] of rig time)."""
        end = self.now + timeout
        while self.driver.why_not_ready() and self.now < end:
            self.poll()
        return not self.driver.why_not_ready()


def _shut_down(*buses):
    for bus in buses:
        bus.shutdown()
