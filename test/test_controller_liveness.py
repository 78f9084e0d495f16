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

"""The driver never trusts silence it has not heard (issue 36 item 1): no stream opens before ControllerHeartbeat,
ControllerStatus and ControllerIdentity have each been received within their silence limits, and a controller
that stops any of them - or never sent one - faults within that limit, counted from its first word on.

The driver runs on simulated time (an injected clock) over a python-can virtual bus against a scripted
controller that sends exactly the frames the test says, so every time asserted is exact; the simulated
controller's `no_heartbeat` defect shows the same on the real simulator.
"""
import can
import numpy as np
import pytest

from rubber_rig.rig import open_rig
from rubber_rig.rig.can.driver import RigDriver
from rubber_rig.rig.can.frames import SampleFrames
from rubber_rig.rig.can.liveness import ControllerLiveness, silence_limits
from rubber_rig.rig.can.protocol import FAULT_WATCHDOG, PROTOCOL_VERSION, STATE_CODE, Protocol
from rubber_rig.rig.can.stream import StreamRefused
from rubber_rig.rig.config import RigConfig

STEP = 0.001     # [s] simulated time between two polls of the driver


class ScriptedController:
    """The controller end of a virtual bus: sends the periodic frames the test enables, at their DBC periods of
    simulated time, and feedback for the setpoints it receives while `ticking`.
    """

    def __init__(self, channel: str, fs: float = 1000.0):
        self.bus = can.Bus(interface='virtual', channel=channel, receive_own_messages=False)
        self.proto = Protocol()
        self.frames = SampleFrames('packed', self.proto.db, fs)
        self.send = {'ControllerHeartbeat': True, 'ControllerStatus': True, 'ControllerIdentity': True}
        self.periods = {'ControllerHeartbeat': 0.05, 'ControllerStatus': 0.01, 'ControllerIdentity': 1.0}
        self.due = dict.fromkeys(self.periods)   # first due at the first step
        self.state, self.counter, self.last_seq, self.pending = 'idle', 0, 0, []
        self.alive = True

    def step(self, now: float):
        """Everything due at simulated time now [s]."""
        msg = self.bus.recv(0)
        while msg is not None:          # take the host's setpoints (ticking is the test's business)
            if msg.arbitration_id in {self.frames.codecs[n].frame_id for n in self.frames.setpoint_names}:
                seq, values = self.frames.decode_setpoints(msg)
                self.pending += [(seq + i, v) for i, v in enumerate(values)]
            msg = self.bus.recv(0)
        if not self.alive:
            return
        for name, period in self.periods.items():
            if self.due[name] is None:
                self.due[name] = now
            if now + 1e-12 >= self.due[name]:
                self.due[name] += period
                if self.send[name]:
                    self.bus.send(self._frame(name))

    def tick(self, n: int):
        """Apply and report n queued setpoints (running), then hold (holding) once they run out."""
        take, self.pending = self.pending[:n], self.pending[n:]
        if take:
            self.state = 'running'
            for k in range(0, len(take), 6):
                chunk = take[k:k + 6]
                vals = [v for _, v in chunk]
                for m in self.frames.encode_feedback(chunk[0][0], vals, [0.0] * len(vals), vals):
                    self.bus.send(m)
            self.last_seq = take[-1][0]
        else:
            self.state = 'holding' if self.state in ('running', 'holding') else self.state

    def _frame(self, name):
        self.counter += 1
        code = STATE_CODE[self.state]
        if name == 'ControllerHeartbeat':
            return self.proto.encode(name, {'HB_Counter': self.counter % 256, 'HB_State': code})
        if name == 'ControllerStatus':
            return self.proto.encode(name, {'ST_State': code, 'ST_Counter': self.counter % 16, 'ST_Faults': 0,
                                            'ST_LastSequence': self.last_seq % (1 << 16), 'ST_BufferLevel': 0})
        return self.proto.encode(name, {'CI_Protocol': PROTOCOL_VERSION, 'CI_Device': 1, 'CI_Firmware': 1,
                                        'CI_HostTimeout': 0.5, 'CI_VelocityMax': 0.5})


@pytest.fixture
def rig(request):
    """(driver, controller, clock) on a virtual bus of its own, simulated time starting at 100 s."""
    channel = f'liveness_{request.node.name}'
    ctrl = ScriptedController(channel)
    clock = [100.0]
    bus = can.Bus(interface='virtual', channel=channel, receive_own_messages=False)
    drv = RigDriver(bus, RigConfig.from_dict({'paced': True}), clock=lambda: clock[0])
    yield drv, ctrl, clock
    drv.bus.shutdown()
    ctrl.bus.shutdown()


def run_until(drv, ctrl, clock, seconds, stop=None, ticks_per_step=0):
    """Advance simulated time by `seconds` in STEP polls; stop early when stop() is true. Returns the time."""
    end = clock[0] + seconds
    while clock[0] < end - 1e-12:
        clock[0] += STEP
        ctrl.step(clock[0])
        if ticks_per_step:
            ctrl.tick(ticks_per_step)
        drv.poll()
        if stop is not None and stop():
            break
    return clock[0]


def watchdog_fault(drv):
    return bool(drv.faults & FAULT_WATCHDOG)


def test_the_silence_limits_follow_the_dbc_periods_and_the_watchdog():
    assert silence_limits(0.1) == {'ControllerHeartbeat': 0.1, 'ControllerStatus': 0.1, 'ControllerIdentity': 2.0}
    assert silence_limits(0.25, require_identity=False) == {'ControllerHeartbeat': 0.25, 'ControllerStatus': 0.25}


def test_counted_in_samples_silence_starts_at_connection_and_a_jump_is_no_silence():
    live = ControllerLiveness({'ControllerHeartbeat': 0.1, 'ControllerStatus': 0.1}, 1000.0, paced=False)
    assert live.silent(0.0, 500) is None                       # nothing heard: nothing owed
    live.heard('ControllerStatus', 0.0, None)                  # connected before any feedback
    assert 'no ControllerHeartbeat' in live.why_not_heard(0.0, None)
    live.jumped(5000)                                          # an idle rig starts its stream at 5000
    assert live.silent(0.0, 5100) is None                      # 100 samples = 0.1 s: at the limit
    live.heard('ControllerStatus', 0.0, 5100)
    name, quiet, ever = live.silent(0.0, 5101)
    assert (name, round(quiet, 6), ever) == ('ControllerHeartbeat', 0.101, False)


def test_a_controller_that_never_sends_a_heartbeat_is_refused_and_faults_from_its_first_word(rig):
    drv, ctrl, clock = rig
    ctrl.send['ControllerHeartbeat'] = False
    t0 = clock[0] + STEP                        # the controller's first frames go out at the first step
    run_until(drv, ctrl, clock, 0.02)
    assert drv.controller_state == 'idle' and drv.controller_identity is not None
    why = drv.why_not_ready()
    assert 'no ControllerHeartbeat received' in why, why
    with pytest.raises(StreamRefused, match='ControllerHeartbeat'):
        drv.open_stream('test')
    t = run_until(drv, ctrl, clock, 1.0, stop=lambda: watchdog_fault(drv))
    # armed at the first status/identity, not at a first heartbeat that never comes: 0.1 s + one poll
    assert watchdog_fault(drv) and 0.1 < t - t0 <= 0.1 + 1.5 * STEP, t - t0
    assert 'heartbeat silent for 0.10' in drv.fault_messages[-1]
    assert 'no ControllerHeartbeat received since the controller was first heard' in drv.fault_messages[-1]
    assert drv.status.state == 'fault'


@pytest.mark.parametrize('frame', ['ControllerHeartbeat', 'ControllerStatus', 'ControllerIdentity'])
def test_a_controller_that_stops_any_periodic_frame_faults_within_its_limit(rig, frame):
    drv, ctrl, clock = rig
    run_until(drv, ctrl, clock, 0.3)
    assert drv.why_not_ready() == '' and not drv.faults
    ctrl.send[frame] = False
    last = ctrl.due[frame] - ctrl.periods[frame]       # the last one sent
    t = run_until(drv, ctrl, clock, 3.0, stop=lambda: watchdog_fault(drv))
    limit = silence_limits(drv.cfg.watchdog_timeout)[frame]
    assert watchdog_fault(drv) and limit < t - last <= limit + 1.5 * STEP, (frame, t - last)
    word = {'ControllerHeartbeat': 'heartbeat', 'ControllerStatus': 'status', 'ControllerIdentity': 'identity'}
    assert f'controller {word[frame]} silent' in drv.fault_messages[-1]
    # a reset judges the silence afresh: the controller, still silent, faults again one limit later
    assert drv.reset() == ''
    t_reset = clock[0]
    assert frame in drv.why_not_ready()                # and no stream opens to it meanwhile
    t = run_until(drv, ctrl, clock, 3.0, stop=lambda: watchdog_fault(drv))
    assert watchdog_fault(drv) and limit < t - t_reset <= limit + 1.5 * STEP


def test_a_controller_killed_while_holding_faults_within_the_watchdog(rig):
    """The issue's case: a controller holding after its program dies; the driver faults in 0.1 s (it had no
    fault after 1.5 s and still reported the rig holding when the controller had never sent a heartbeat).
    """
    drv, ctrl, clock = rig
    run_until(drv, ctrl, clock, 0.1)
    grant = drv.open_stream('test')
    assert drv.queue_setpoints(grant.first_sequence, np.zeros(200), grant.stream_id)
    drv.end_stream(grant.stream_id)       # the program ends: the controller holds its last command
    run_until(drv, ctrl, clock, 0.4, ticks_per_step=1)
    assert drv.controller_state == 'holding' and not drv.faults, drv.fault_messages
    ctrl.alive = False
    t_dead = clock[0]
    t = run_until(drv, ctrl, clock, 1.5, stop=lambda: watchdog_fault(drv))
    assert watchdog_fault(drv) and t - t_dead <= 0.1 + 1.5 * STEP + 0.01, t - t_dead
    assert drv.status.state == 'fault'


def test_a_controller_never_heard_is_not_ready_and_not_faulted(rig):
    drv, ctrl, clock = rig
    ctrl.alive = False
    run_until(drv, ctrl, clock, 2.0)
    assert not drv.faults and 'has not announced itself' in drv.why_not_ready()


def test_the_simulator_without_heartbeat_is_refused_paced_and_fast():
    """The simulated controller's no_heartbeat defect: the driver never streams to it; paced it faults."""
    with open_rig({'paced': False, 'sim': {'defects': ['no_heartbeat']}}) as rig:
        assert not rig.wait_ready(1.0)
        assert 'no ControllerHeartbeat' in rig.driver.why_not_ready()
        with pytest.raises(StreamRefused):
            rig.driver.open_stream('test')
    with open_rig({'paced': True, 'sim': {'defects': ['no_heartbeat']}}) as rig:
        assert not rig.wait_ready(1.0)
        drv = rig.driver
        assert watchdog_fault(drv) and 'no ControllerHeartbeat received' in drv.fault_messages[0]
        with pytest.raises(StreamRefused):
            drv.open_stream('test')
