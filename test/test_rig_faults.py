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

"""Fault injection on the simulated rig: each fault is detected by the driver and ends in the safe ramp
(the controller's applied command moves smoothly back to rest). Limits and bad frames too."""
import time

import numpy as np
import pytest

from rubber_rig.excitation import Program
from rubber_rig.rig import (
    FAULT_BUS,
    FAULT_DISPLACEMENT_LIMIT,
    FAULT_FORCE_LIMIT,
    FAULT_SENSOR,
    FAULT_VELOCITY_LIMIT,
    FAULT_WATCHDOG,
    open_rig,
)
from rubber_rig.session import run_program

from support.rig import FAST, contiguous_diffs, contiguous_second_diffs

PROG = Program.from_yaml_text('name: f\nblocks:\n  - {waveform: sine, frequency: 5 Hz, amplitude: 1 mm, '
                              'cycles: 10}\n')
PROGRAM_V = 2 * np.pi * 5 * 1e-3


def assert_safe_ramp(r, t_fault):
    """After the fault the applied command decelerates without a step and settles at rest (0 m)."""
    du = contiguous_diffs(r.sequence, r.setpoint) * r.sample_rate
    assert np.max(np.abs(du)) <= PROGRAM_V * 1.001                      # never faster than the program
    ddu = contiguous_second_diffs(r.sequence, r.setpoint) * r.sample_rate ** 2
    assert np.max(np.abs(ddu)) < 1.05 * max(20.0, (2 * np.pi * 5) ** 2 * 1e-3)   # no velocity jump
    after = r.time > t_fault + 0.05
    assert np.any(after)
    assert r.setpoint[-1] == 0.0 and abs(r.displacement[-1]) < 5e-6
    ramp = np.nonzero((r.block_index == -1) & (r.time > t_fault))[0]
    assert ramp.size >= 5 and np.all(r.block_index[ramp[0]:] == -1)   # once ramping, no program sample follows


FAULTS = {
    # name: (fault specs, expected driver fault bit, message fragment)
    'drop_burst': ([{'type': 'drop', 'start': 0.5, 'duration': 0.05}], FAULT_BUS, 'bad frames'),
    'corrupt': ([{'type': 'corrupt', 'start': 0.5, 'duration': 0.1}], FAULT_BUS, 'bad frames'),
    'duplicate': ([{'type': 'duplicate', 'start': 0.5, 'duration': 0.1}], FAULT_BUS, 'bad frames'),
    'delay': ([{'type': 'delay', 'start': 0.5, 'delay': 0.3}], FAULT_WATCHDOG, 'behind the controller'),
    'stuck_displacement': ([{'type': 'stuck_sensor', 'start': 0.5, 'sensor': 'displacement'}], FAULT_SENSOR,
                           'displacement sensor stuck'),
    'stuck_force': ([{'type': 'stuck_sensor', 'start': 0.5, 'sensor': 'force'}], FAULT_SENSOR,
                    'force sensor stuck'),
    'silent_controller': ([{'type': 'silent_controller', 'start': 0.5}], FAULT_WATCHDOG, 'heartbeat silent'),
}


@pytest.mark.parametrize('name', sorted(FAULTS))
def test_fault_is_detected_and_ends_in_safe_ramp(name):
    faults, bit, text = FAULTS[name]
    r = run_program(PROG, dict(FAST, sim={'faults': faults}))
    st = r.final_status
    assert not r.completed
    assert st.faults & bit, (name, st.faults, st.fault_messages)
    assert any(text in m for m in st.fault_messages), st.fault_messages
    assert st.state == 'fault'
    assert r.blocks[0].completed is False
    # detected promptly: the ramp starts within 0.2 s of rig time after the fault
    ramp = np.nonzero((r.block_index == -1) & (r.time > 0.5))[0]
    assert ramp.size and r.time[ramp[0]] < 0.5 + 0.2
    if name == 'stuck_displacement':   # the stuck transducer cannot show the ramp; the applied command does
        assert r.setpoint[-1] == 0.0
        return
    assert_safe_ramp(r, 0.5)


def test_counters_for_occasional_bad_frames_without_fault():
    faults = [{'type': 'drop', 'probability': 0.005, 'frames': ['Feedback']},
              {'type': 'corrupt', 'probability': 0.002, 'frames': ['Feedback', 'Temperature']},
              {'type': 'duplicate', 'probability': 0.003}]
    r = run_program(PROG, dict(FAST, sim={'faults': faults}))
    st = r.final_status
    assert r.completed, r.message
    assert st.frames_lost > 0 and st.frames_malformed > 0 and st.frames_late > 0
    # every missing sample is accounted for as lost (a corrupted feedback frame is also a lost sample)
    n = PROG.n_samples(1000.0)
    assert st.frames_lost == n - np.count_nonzero(r.sequence < n)
    assert r.blocks[0].achieved_amplitude == pytest.approx(1e-3, rel=0.01)


def test_force_limit_trips_and_ramps():
    r = run_program(PROG, dict(FAST, limits={'force_max': 8e3}))
    st = r.final_status
    assert st.faults & FAULT_FORCE_LIMIT and 'force' in st.fault_messages[0]
    assert_safe_ramp(r, 0.0)


def test_host_silence_makes_the_controller_ramp_on_its_own():
    with open_rig({'paced': False, 'sim': {'host_timeout': 0.2}}) as rig:
        assert rig.wait_ready(5.0)
        drv, sim = rig.driver, rig.sim
        t = np.arange(1500) / 1000.0
        x = 1e-3 * np.sin(2 * np.pi * 5 * t) * np.minimum(t / 0.2, 1.0) ** 2
        # stream setpoints without the driver's heartbeats: a dead host, as the controller sees it (the stream
        # announced as every stream must be: CTRL-PWR-1, no setpoint before a HostStreamStart)
        drv.bus.send(drv.proto.encode('HostStreamStart', {'HS_FirstSequence': 0}))
        for msg in drv.frames.encode_setpoints(0, x.tolist()):
            drv.bus.send(msg)
        for _ in range(200000):
            drv.poll()
            if drv.controller_state == 'fault':
                break
        assert sim.fault_bits & FAULT_WATCHDOG and drv.status.state == 'fault'
        assert abs(sim.u) == 0.0 and sim.ramp.done


def test_setpoints_outside_limits_are_refused_before_sending():
    with open_rig({'paced': False, 'limits': {'displacement_max': 1e-3, 'velocity_max': 0.1}}) as rig:
        assert rig.wait_ready(5.0)
        drv = rig.driver
        assert not drv.queue_setpoints(0, np.array([0.0, 0.5e-3, 1.5e-3]))
        st = drv.status
        assert st.faults & FAULT_DISPLACEMENT_LIMIT and st.setpoints_sent == 0
        assert not drv.queue_setpoints(0, np.zeros(3))          # refused while faulted
        drv.reset()
        assert drv.status.faults == 0
        assert not drv.queue_setpoints(0, np.array([0.0, 0.2e-3]))   # 0.2 m/s step
        assert drv.status.faults & FAULT_VELOCITY_LIMIT and drv.status.setpoints_sent == 0


def abort_at(seconds: float):
    """A before_chunk for run_program that aborts the program at `seconds` of samples (the abort path)."""
    def abort(run, sequence):
        runner = run.session.runner
        if sequence >= run.session.start_sequence + int(round(seconds * runner.fs)) and not runner.aborted:
            runner.abort('abort_after')
    return abort


def test_abort_ramp_respects_the_host_velocity_limit():
    prog = Program.from_yaml_text('name: slow\nblocks:\n  - {waveform: sine, frequency: 1 Hz, amplitude: 1 mm, '
                                  'cycles: 5}\n')
    r = run_program(prog, dict(FAST, limits={'velocity_max': 0.01}), before_chunk=abort_at(2.3))
    assert not r.completed and r.setpoint[-1] == 0.0
    ramp = r.block_index == -1
    v = np.abs(contiguous_diffs(r.sequence, r.setpoint)) * r.sample_rate
    assert np.max(v[ramp[1:]]) <= 0.005 + 1e-4          # half the 10 mm/s limit (+ 0.1 um resolution)
    # the controller's own ramp after a fault gets the same bound through HostCommand.CMD_RampVelocity
    r = run_program(prog, dict(FAST, limits={'velocity_max': 0.01, 'force_max': 8e3}))
    assert r.final_status.faults & FAULT_FORCE_LIMIT and r.setpoint[-1] == 0.0
    ramp = r.block_index == -1
    v = np.abs(contiguous_diffs(r.sequence, r.setpoint)) * r.sample_rate
    assert np.max(v[ramp[1:]]) <= 0.005 + 1e-4


# system tier: the flood, the controller's transmit queue and the driver's watchdog run on the wall clock of the
# paced simulated bus, and "the ramp begins within 0.35 s" is judged on it. Under a load of 7 on two cores (issue
# 34's session) one run failed the velocity bound - an applied step of 0.23 mm in one sample - and passed alone;
# not yet explained (a stalled paced controller catching up, or a real defect), so it stays a test, in this tier.
# The bus timing itself is test_simbus.py's, on a simulated clock.
@pytest.mark.system
def test_bus_overload_mid_run_faults_safely_and_counts_the_loss():
    """Paced, on the timed bus: from 0.6 s another node floods the bus with frames of higher priority than the
    rig's stream. The controller's frames queue, then its transmit queue overflows and samples are lost; the
    driver counts every one, faults and the rig ramps to rest inside its limits. The next program runs on the
    same rig once the flood is gone."""
    flood = {'type': 'bus_flood', 'start': 0.6, 'duration': 0.4, 'load': 1.0, 'frame_id': 0x0F0}
    # a transmit queue of 128 frames (SocketCAN's default is 10, high-rate setups use 1000) fills within the flood
    cfg = {'paced': True, 'watchdog_timeout': 0.25, 'tx_queue': 128, 'sim': {'faults': [flood]}}
    with open_rig(cfg) as rig:
        assert rig.wait_ready(5.0)
        r = run_program(PROG, cfg, rig=rig)
        st = r.final_status
        assert not r.completed and st.state == 'fault'
        assert st.faults & (FAULT_BUS | FAULT_WATCHDOG), st.fault_messages
        assert rig.sim.counters['tx_dropped'] > 0
        assert 0.55 < r.time[np.flatnonzero(r.block_index == -1)[0]] < 0.6 + 0.35   # ramp within 0.35 s
        assert np.max(np.abs(contiguous_diffs(r.sequence, r.setpoint))) * r.sample_rate <= PROGRAM_V * 1.001
        assert st.extra['bus_load_measured'] is not None
        deadline = time.monotonic() + 1.0            # the flood ends at 1.0 s of rig time (idle time counts)
        while time.monotonic() < deadline:
            rig.driver.poll()
            time.sleep(0.002)
        # every sample the rig took and the host never received is counted lost (nothing silently missing)
        st = rig.driver.status
        assert st.frames_lost > 0 and st.samples_received + st.frames_lost == rig.sim.next_seq
        # the rig ramped to rest at 0 (on the host's abort, whose identifier beats the flood, or on its own watchdog)
        assert rig.sim.state in ('idle', 'fault') and rig.sim.u == 0.0 and abs(rig.sim.actuator.x) < 5e-6
        assert st.state == 'fault'
        assert rig.driver.reset() == ''
        again = run_program(PROG, cfg, rig=rig)
        assert again.completed and again.final_status.frames_lost == st.frames_lost, again.message


def test_setpoints_of_an_aborted_stream_never_restart_the_rig():
    """Setpoint frames still queued on the bus when a stream is aborted reach the controller after its ramp: it
    takes none until the host announces the next stream (HostStreamStart), and none below that stream's start."""
    with open_rig(FAST) as rig:
        assert rig.wait_ready(5.0)
        drv, sim = rig.driver, rig.sim
        x = 1e-3 * np.sin(2 * np.pi * 5 * np.arange(400) / 1000.0) * np.minimum(np.arange(400) / 200, 1) ** 2
        assert drv.queue_setpoints(0, x)
        stale = drv.frames.encode_setpoints(400, (x[:100] * 0 + 2e-3).tolist())   # queued, not yet on the bus
        for _ in range(50):
            drv.poll()
        drv.abort('test abort')
        for _ in range(2000):
            drv.poll()
            if sim.state == 'idle':
                break
        assert sim.state == 'idle' and sim.u == 0.0
        ticks = sim.next_seq
        for msg in stale:                           # they arrive now, after the ramp
            drv.bus.send(msg)
        for _ in range(50):
            drv.poll()
        assert sim.state == 'idle' and sim.next_seq == ticks and sim.counters['setpoints_stale'] == len(stale)
        first = drv.next_sequence
        assert first >= 400                         # the next stream starts after every setpoint ever sent
        assert drv.queue_setpoints(first, np.zeros(50))
        for _ in range(200):
            drv.poll()
        assert sim.next_seq == first + 50 and sim.counters['setpoints_stale'] == len(stale)
