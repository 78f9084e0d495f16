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

"""Issue 34: the embedded simulator's lateness (rig.sim.lateness) is this host's, never the rig's silence; a real
controller's silence still faults. On simulated time (rig.stepped.SteppedRig): the controller "starved" is one the
steps do not serve for a while, as a busy computer does not schedule rig_driver's simulator thread.
"""
import math

import numpy as np
import pytest

from rubber_rig.rig.can.protocol import FAULT_WATCHDOG
from rubber_rig.rig.sim.lateness import LatenessLedger
from rubber_rig.rig.stepped import SteppedRig

FS = 1000.0
STARVED_AT = 0.5          # [s] after the stream's start


def run_stream(embedded: bool, starved_for: float, streaming: bool = True, seconds: float = 4.0):
    """A 2 s sine (1 mm, 2 Hz, tapered) queued at once and ended, on a rig whose controller is not served from
    STARVED_AT for `starved_for` [s]; returns (driver, [s] after the start the first fault came, or None).
    streaming False: the rig stands idle, and only its heartbeats and status fall silent.
    """
    rig = SteppedRig({'stream_timeout': 0.15}, embedded=embedded)
    assert rig.wait_ready(5.0)
    drv = rig.driver
    if streaming:
        g = drv.open_stream('/rig1/excitation')
        t = np.arange(2000) / FS
        x = 1e-3 * np.sin(2 * np.pi * 2 * t) * np.minimum(t / 0.3, 1.0) ** 2 * np.minimum((2.0 - t) / 0.3, 1.0) ** 2
        assert drv.queue_setpoints(g.first_sequence, x, g.stream_id)
        drv.end_stream(g.stream_id)
    t0 = rig.now
    while rig.now < t0 + seconds:
        rig.advance(serve=not STARVED_AT <= rig.now - t0 < STARVED_AT + starved_for)
        while drv.poll() is not None:
            pass
        if drv.status.faults:
            return drv, rig.now - t0
    return drv, None


@pytest.mark.parametrize('starved_for', [0.3, 0.8])
def test_an_embedded_simulator_starved_by_its_host_does_not_fault_the_driver(starved_for):
    """The fault matrix saw 'no feedback for 0.264 s' when rig_driver's process did not schedule its simulator
    thread: the simulator ticked the missed samples at once when it woke (as it does), and the driver blamed the
    rig for the host's absence. With the simulator's ledger the driver excuses that time: the stream plays every
    sample and completes."""
    drv, fault_at = run_stream(True, starved_for)
    assert fault_at is None, drv.status.fault_messages
    assert 'completed at sample' in drv.last_event
    assert drv.counters['frames_lost'] == 0


def test_an_idle_embedded_simulator_starved_by_its_host_is_not_called_silent():
    drv, fault_at = run_stream(True, 0.8, streaming=False, seconds=2.0)
    assert fault_at is None, drv.status.fault_messages
    assert drv.why_not_ready() == ''


@pytest.mark.parametrize('streaming', [True, False])
def test_a_real_controller_silent_as_long_faults_the_watchdog_within_its_timeout(streaming):
    """The same silence from a controller with its own CPU (no ledger): the watchdog faults, as it must, within
    watchdog_timeout (0.1 s) plus a poll of the first silent moment (the idle rig's heartbeat is owed at its
    period)."""
    drv, fault_at = run_stream(False, 0.3, streaming=streaming, seconds=2.0)
    assert fault_at is not None and drv.status.faults & FAULT_WATCHDOG
    budget = 0.1 + 0.002 + (0.0 if streaming else 0.1)
    assert STARVED_AT < fault_at <= STARVED_AT + budget, (fault_at, drv.status.fault_messages)


def test_an_embedded_simulator_stuck_longer_than_the_ledger_excuses_faults_like_a_real_one():
    """A simulator that does not wake for longer than the ledger's cap (1 s: a busy computer delays a thread
    0.3-0.8 s) is stuck or dead, not starved: the driver faults at the cap plus watchdog_timeout."""
    drv, fault_at = run_stream(True, 3.0)
    assert fault_at is not None and drv.status.faults & FAULT_WATCHDOG
    assert STARVED_AT + 1.0 < fault_at <= STARVED_AT + 1.0 + 0.1 + 0.002, fault_at


def test_the_ledger_adds_missed_deadlines_and_the_current_overdue_up_to_its_cap_and_nothing_once_stopped():
    ledger = LatenessLedger(cap=1.0)
    assert ledger.behind(5.0) == 0.0                      # nothing due yet
    ledger.due(10.0)
    assert ledger.behind(9.0) == 0.0 and ledger.behind(10.25) == pytest.approx(0.25)
    ledger.missed(0.3, 10.301)                            # woke 0.3 s late, caught up, next due at 10.301
    assert ledger.behind(10.3005) == pytest.approx(0.3)
    assert ledger.behind(12.0) == pytest.approx(0.3 + 1.0)   # overdue counted up to the cap
    ledger.stopped()
    assert ledger.behind(20.0) == pytest.approx(0.3) and not math.isinf(ledger.behind(20.0))
