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

"""Bringing a rig to rest before its bus closes: the wait of a shutting-down driver, ROS-free, on an injected clock.

The rig_driver node closes the bus on cleanup and shutdown; a rig that still moves is first sent its safe ramp to
rest and polled until the controller reports the ramp done. The wait ends early when the controller is silent (a
watchdog fault): one that reports nothing would hold the exit for the whole wait (5 s measured), and it ramps to
rest on its own once the host heartbeat stops (host_timeout). An idle rig does not wait at all.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

from .can import FAULT_WATCHDOG

RAMP_WAIT = 5.0          # [s] the longest wait for a moving rig's ramp to rest to end
POLL_PERIOD = 0.005      # [s] between two polls of the driver while it ramps
MOVING = ('running', 'holding', 'ramping_down')
AT_REST = ('idle', 'fault')


@dataclass(frozen=True)
class RampToRest:
    """What ramp_to_rest did: ``ramped`` (the rig was moving and was sent its ramp), ``waited`` [s, clock
    time], the controller ``state`` at the end and why the wait ended: ``at_rest``, ``silent`` (watchdog fault:
    not waited for) or ``timed_out``.
    """

    ramped: bool
    waited: float
    state: str
    ending: str

    @property
    def message(self) -> str:
        """A log line for the node ('' when nothing is worth saying)."""
        if self.ending == 'silent':
            return ('controller silent (watchdog fault): not waiting for its ramp to rest; it ramps to rest on its '
                    'own once the host heartbeat stops')
        if self.ending == 'timed_out':
            return (f'the controller still reports {self.state} after {self.waited:.1f} s of its ramp to rest: '
                    'closing anyway (it ramps to rest on its own once the host heartbeat stops)')
        return ''


def ramp_to_rest(driver, reason: str, wait: float = RAMP_WAIT, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, period: float = POLL_PERIOD) -> RampToRest:
    """Send a moving rig (RigDriver ``driver``) its safe ramp to rest (``reason`` in its log) and poll it until the
    controller is at rest, silent, or ``wait`` [s] of ``clock`` time have passed, sleeping ``period`` [s]
    between polls. An idle rig is left as it is.
    """
    if driver.controller_state not in MOVING:
        return RampToRest(False, 0.0, driver.controller_state, 'at_rest')
    driver.abort(reason)
    start = clock()
    while True:
        silent = bool(driver.faults & FAULT_WATCHDOG)
        state = driver.controller_state
        waited = clock() - start
        if state in AT_REST:
            return RampToRest(True, waited, state, 'at_rest')
        if silent:
            return RampToRest(True, waited, state, 'silent')
        if waited >= wait:
            return RampToRest(True, waited, state, 'timed_out')
        driver.poll()
        sleep(period)
