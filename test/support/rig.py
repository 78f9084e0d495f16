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

"""Shared helpers of the rig tests (not a test module)."""
import dataclasses

import numpy as np

from rubber_rig.rig.can.bus import open_bus, sim_channel_name
from rubber_rig.rig.can.driver import RigDriver
from rubber_rig.rig.can.protocol import Protocol
from rubber_rig.rig.config import RigConfig, SimOptions
from rubber_rig.rig.sim.controller import SimController
from rubber_rig.rig.sim.plant import Actuator
from rubber_rig.rig.sim.specimen import build_specimen

FAST = {'paced': False}


def expected_plant(result, options: SimOptions = None):
    """Noise-free actuator position [m] and specimen force [N] for the applied commands of a RunResult
    (the run must have no lost samples)."""
    opt = options or SimOptions()
    act = Actuator(opt.actuator_frequency, opt.actuator_damping, opt.actuator_velocity_max, result.sample_rate)
    x = np.array([act.step(u) for u in result.setpoint])
    model = build_specimen(opt.specimen, 1.0 / result.sample_rate)
    f = np.array([model.step(float(v)) for v in x])
    return x, f


def poll_samples(drv, got, n, tries):
    """Poll the driver (at most `tries` times), appending its SampleBlocks to `got`, until `got` holds at least n
    samples and a poll finds nothing more; return the number of samples in `got`."""
    for _ in range(tries):
        b = drv.poll()
        if b is not None:
            got.append(b)
        elif sum(len(g) for g in got) >= n:
            break
    return sum(len(g) for g in got)


def contiguous_diffs(seq, values):
    """np.diff of values only between consecutive sequence numbers (gaps from lost frames skipped)."""
    ok = np.diff(seq) == 1
    return np.diff(values)[ok]


def contiguous_second_diffs(seq, values):
    """Second differences of values only over three consecutive sequence numbers."""
    seq = np.asarray(seq)
    ok = (seq[2:] - seq[:-2]) == 2
    return (values[2:] - 2 * values[1:-1] + values[:-2])[ok]


class FastRig:
    """The real RigDriver and simulated controller on a python-can virtual bus, unpaced (the controller runs the
    setpoints as they are queued) and on simulated time: the driver's clock is the rig's sample count, so the
    result does not depend on how busy the computer is.
    """

    def __init__(self, config: dict = None, clock=None, pumped: bool = True, driver_paced: bool = False):
        """config: RigConfig fields over {'paced': False}; clock: the driver's (default: the rig's sample count
        [s]); pumped False: the controller is never run (a silent controller); driver_paced: the driver judges
        silence on its clock as it does for a real-time rig (unpaced it counts samples, and a controller that
        sends none is never silent).
        """
        self.cfg = RigConfig.from_dict({**(config or {}), 'paced': False})
        proto, channel = Protocol(), sim_channel_name()
        self._buses = open_bus(self.cfg, channel), open_bus(self.cfg, channel)
        self.sim = SimController(self._buses[1], self.cfg.sample_rate, self.cfg.sim, False, proto)
        driver_cfg = RigConfig.from_dict({**(config or {}), 'paced': driver_paced}) if driver_paced else self.cfg
        self.drv = RigDriver(self._buses[0], driver_cfg, proto, clock=clock or (lambda: self.now))
        if pumped:
            self.drv.pump = self.sim.pump
        self.samples = {}                     # sequence -> (applied command [m], measured displacement [m])
        self.got = []                         # SampleBlocks in arrival order, not yet handed to the session

    @property
    def now(self) -> float:
        return max(self.sim.ticks, 0) / self.cfg.sample_rate

    def poll(self) -> None:
        for _ in range(10000):
            blk = self.drv.poll()
            if blk is None:
                return
            self.got.append(blk)
            for i in range(len(blk)):
                self.samples[blk.first_sequence + i] = (float(blk.setpoint[i]), float(blk.displacement[i]))

    def wait_ready(self) -> None:
        for _ in range(1000):
            self.poll()
            if self.drv.controller_state != 'unconfigured':
                return
        raise AssertionError('the simulated controller did not announce itself')

    def feed(self, session, upto) -> None:
        """Hand the session the measured samples below sequence `upto` (the rest wait: measurement latency)."""
        keep = []
        for blk in self.got:
            n = min(len(blk), max(0, upto - blk.first_sequence))
            if n == len(blk):
                session.measured(blk.first_sequence, blk.displacement, blk.setpoint)
            elif n:
                session.measured(blk.first_sequence, blk.displacement[:n], blk.setpoint[:n])
                keep.append(dataclasses.replace(blk, first_sequence=blk.first_sequence + n,
                                                displacement=blk.displacement[n:], force=blk.force[n:],
                                                setpoint=blk.setpoint[n:]))
            else:
                keep.append(blk)
        self.got = keep

    def close(self):
        self.drv.close(ramp=False)
        for bus in self._buses:
            bus.shutdown()
