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

"""rubber_rig.rig.shutdown: the wait of a shutting-down rig driver for its ramp to rest, on simulated time (the
clock advances by what the wait sleeps), with the real RigDriver and simulated controller on a virtual bus.
"""
import numpy as np
import pytest

from rubber_rig.rig.shutdown import RAMP_WAIT, ramp_to_rest

from support.rig import FastRig


class SimulatedTime:
    """A clock [s] that moves only when the code under test sleeps."""

    def __init__(self):
        self.now, self.sleeps = 0.0, 0

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds
        self.sleeps += 1


def moving_rig(clock, config=None, pumped=True):
    """A rig running a 1 mm, 2 Hz sine when the shutdown comes (pumped False: its controller then falls silent).
    The driver judges silence on the clock, as for a real-time rig; the controller runs as it is polled.
    """
    rig = FastRig(config, clock=clock, driver_paced=True)
    rig.wait_ready()
    x = 1e-3 * np.sin(2 * np.pi * 2.0 * np.arange(300) / rig.cfg.sample_rate)
    assert rig.drv.queue_setpoints(0, x)
    for _ in range(100):
        rig.poll()
        if rig.drv.controller_state == 'running' and rig.sim.next_seq >= 200:
            break
    assert rig.drv.controller_state == 'running'
    if not pumped:
        rig.drv.pump = None
    return rig


def test_an_idle_rig_closes_without_waiting():
    clock = SimulatedTime()
    rig = FastRig(clock=clock)
    try:
        rig.wait_ready()
        done = ramp_to_rest(rig.drv, 'test', clock=clock, sleep=clock.sleep)
        assert (done.ramped, done.waited, done.ending, clock.sleeps) == (False, 0.0, 'at_rest', 0)
    finally:
        rig.close()


def test_a_moving_rig_is_ramped_to_rest_before_the_bus_closes():
    clock = SimulatedTime()
    rig = moving_rig(clock)
    try:
        done = ramp_to_rest(rig.drv, 'test shutdown', clock=clock, sleep=clock.sleep)
        assert done.ramped and done.ending == 'at_rest' and done.state == 'idle' and done.message == ''
        assert done.waited < 0.1                                   # the unpaced controller ramps as it is polled
        assert abs(rig.drv.status.extra['position']) < 1e-6       # at rest (rest_position 0)
    finally:
        rig.close()


def test_a_silent_controller_is_not_waited_for_beyond_the_watchdog():
    """The controller stops answering as the shutdown comes: the driver's watchdog (0.1 s) faults it and the wait
    ends then, not after RAMP_WAIT; the log line says the controller ramps on its own."""
    clock = SimulatedTime()
    rig = moving_rig(clock, pumped=False)
    try:
        done = ramp_to_rest(rig.drv, 'test shutdown', clock=clock, sleep=clock.sleep)
        assert done.ending == 'silent' and 'watchdog' in done.message
        assert rig.drv.cfg.watchdog_timeout <= done.waited < rig.drv.cfg.watchdog_timeout + 0.05
    finally:
        rig.close()


@pytest.mark.parametrize('wait', [0.05, RAMP_WAIT])
def test_the_wait_ends_after_its_time_when_the_controller_neither_rests_nor_is_declared_silent(wait):
    """A watchdog longer than the wait (10 s here): a silent controller is waited for `wait` s of clock time."""
    clock = SimulatedTime()
    rig = moving_rig(clock, config={'watchdog_timeout': 10.0}, pumped=False)
    try:
        done = ramp_to_rest(rig.drv, 'test shutdown', clock=clock, sleep=clock.sleep, wait=wait)
        assert done.ending == 'timed_out' and wait <= done.waited < wait + 0.006, done
        assert 'still reports running' in done.message
    finally:
        rig.close()
