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

"""Fault matrix: the four nodes as separate processes (as a launch file starts them), driven from outside
through their ROS interfaces only, through every abnormal path (README 'Safety'). After each one:

(a) the applied command never left the limits and never stepped faster than velocity_max;
(b) the rig ends at rest (or in an operator-commanded hold), and status says why;
(c) the goal ended with a reason within 1 s of the event;
(d) the next program completes without restarting a node or cycling the lifecycle by hand;
(e) every lost sample is counted in the recording: checked (every sample the operator saw is in the live
    recording or counted there as lost) for the happy path, driver abort, excitation SIGKILL and every
    simulated rig fault. Not after SIGKILL of the driver (samples that die with it were never published) or
    of the recorder (its unflushed tail is reported as unaccounted, test_recorder_failures.py).

One suite serves the module (tests run in file order and leave it ready for the next). Waits are bounded
waits on conditions. Paced rig at 1 kHz, limits +-2.5 mm / 0.2 m/s (tighter than rig_sim.yaml so the 14 Hz,
2.2 mm sine of the issue runs near them)."""
import math
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters

from msg_defs.msg import RecorderStatus, RigStatus
from msg_defs.srv import LoadProgram
from rubber_rig.nodes.auth import SAMPLES
from rubber_rig.recording import load_recording
from rubber_rig.rig.config import RigConfig
from rubber_rig.session.liveness import OWNER_TIMEOUT
from rubber_rig.session.program_session import LEAD_TIME
from rubber_rig.testing.operator import Operator
from rubber_rig.testing.processes import SuiteProcesses

from support.waiting import wait_for

# timeout: a scenario chains bounded waits (a node restart 30 s, the rig ready 60 s, the goal 40-60 s, the next
# program 80 s; the first test also starts the suite, 90 s) that add up to more than the 300 s default: a
# scenario that goes wrong must fail on its own assertion, which says what did not happen, not on the timeout.
# Measured here: 3-10 s per scenario, about 70 s for the module.
pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.timeout(600)]
# Tiers: make test runs the happy path and the two kill-and-restart scenarios (the wiring of goal, stream,
# heartbeats, recording and restarts across processes). Every other scenario is the system tier's
# (make test-system): each judges, on the wall clock of the paced rig, that the goal ends within about a second of
# the event while five processes share two cores - a busy computer delays that and fails them, the product is
# not at fault. Their logic (stream loss, owner watch, supervisor, gate, limits) is tested on simulated time in
# test_rig_safety_core.py, test_heartbeat.py, test_rig_driver_parts.py and test_program_session.py.
system = pytest.mark.system

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'rig_sim.yaml'
NS = '/fm'
FS = 1000.0
D_MAX, V_MAX = 2.5e-3, 0.2
FAST_SINE = """name: fast
blocks:
  - {name: s14, waveform: sine, frequency: 14 Hz, amplitude: 2.2 mm, cycles: 70, taper_cycles: 1}
"""
SHORT = """name: short
blocks:
  - {name: s5, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 5, taper_cycles: 1}
"""
SLOW_TRIANGLE = """name: slow
blocks:
  - {name: tri, waveform: triangle, frequency: 0.1 Hz, amplitude: 0.5 mm, cycles: 1}
"""


def domain_id() -> int:
    return 150 + os.getpid() % 50


# [s] rig_driver's stream_timeout, the default here: it is the reserve of setpoints a silent stream is lost at (not a
# silence limit), so a larger one only makes a stalled excitation lose its stream sooner (0.5 s here did, under load:
# 'no setpoints from /fm/excitation for 0.566 s (498 ms of setpoints left)')
STREAM_TIMEOUT = RigConfig().stream_timeout


@pytest.fixture(scope='module')
def suite(tmp_path_factory):
    base = tmp_path_factory.mktemp('fault_matrix')
    overrides = {
        # 50-sample batches read every 10 ms (not the 10 ms / 2 ms defaults that keep predictions within 25 ms): five
        # node processes, the simulated rig and the operator share two cores here; this matrix tests faults
        'rig_driver': {'limits': {'displacement_min': -D_MAX, 'displacement_max': D_MAX, 'velocity_max': V_MAX},
                       'batch_size': 50, 'poll_period': 0.01},
        'recorder': {'output_dir': str(base / 'recordings')},
        'excitation': {'require_recording': True, 'amplitude_control': False},
    }
    procs = SuiteProcesses(CONFIG, NS, domain_id(), base / 'logs', overrides)
    procs.start_all()
    op = Operator(NS, domain_id())
    try:
        assert op.wait_ready(60.0), 'suite did not come up:\n' + procs.log('rig_driver')[-2000:]
        assert op.wait_for(lambda: op.recorder is not None and op.recorder.state == RecorderStatus.STATE_RECORDING
                           and f'{NS}/samples' in op.recorder.topics, 30.0), 'recorder not recording'
        yield procs, op, base
    finally:
        op.close()
        procs.stop_all()


@pytest.fixture(autouse=True)
def from_a_ready_rig(suite, request):
    """Each scenario starts from a ready rig, and one that fails shows why: the tail of every node's log.
    A failed scenario can leave the rig faulted; acknowledging that here keeps one failure one failure (the
    scenarios that pass leave the rig ready on their own, checked by next_program_completes)."""
    procs, op, base = suite
    for _ in range(5):
        if op.status is None or op.status.state != RigStatus.STATE_FAULT:
            break
        print(f'rig faulted at the start of {request.node.name}: {list(op.status.fault_messages)}; reset')
        op.trigger('rig_driver/reset')
        op.wait_ready(2.0)
    yield
    rep = getattr(request.node, 'rep_call', None)
    if rep is not None and rep.failed:
        for name in ('rig_driver', 'excitation', 'recorder', 'element_model'):
            print(f'--- {name} log (tail) ---\n' + procs.log(name)[-3000:])


# -- the invariants -----------------------------------------------------------------------------------------
def assert_applied_safe(op, since=0):
    """(a) the applied command stayed inside the limits and never stepped faster than velocity_max."""
    seq, u, _ = op.applied(since)
    assert seq.size, 'no samples'
    assert u.min() >= -D_MAX - 1e-9 and u.max() <= D_MAX + 1e-9, (u.min(), u.max())
    contiguous = np.diff(seq) == 1
    v = np.abs(np.diff(u))[contiguous] * FS
    assert v.max() <= V_MAX * (1 + 1e-6) + 1.5e-7 * FS, v.max()   # + one 0.1 um frame quantum
    return seq, u


def stream_start(op, since: int) -> int:
    """First sample of the program streamed after `since` (its first setpoint batch). The excitation starts a
    stream only once the recorder has matched the rig's samples, so from here on every sample must be recorded
    or counted lost. Idle samples of a restarted driver before the recorder matched it are counted lost by the
    recording (a restart gap) but are not part of the run."""
    firsts = [b.first_sequence for b in op.setpoints_seen if b.first_sequence >= since and len(b.displacement)]
    return min(firsts) if firsts else since


def assert_recorded(op, base, since, t_wall):
    """(e) every sample from `since` to the last one the operator received is in the live recording or
    counted there as lost (gap events). t_wall: time.time() before the first of these samples (separates
    them from equal sequence numbers of a rig before a driver restart). Returns (recorded, lost, judged):
    judged is the number of samples from `since` to the operator's last one when this was called (the idle
    rig goes on sampling after a program, so it can exceed what an earlier look at the operator saw)."""
    seq_op, _, _ = op.applied(since)
    end = int(seq_op[-1]) + 1
    state = {}

    def read():
        live = max((base / 'recordings').rglob('*.mcap'), key=lambda p: p.stat().st_mtime)
        rec = load_recording(live.parent, allow_truncated=True)
        keep = (rec.sequence >= since) & (rec.sequence < end) & (rec.time_ns >= (t_wall - 0.5) * 1e9)
        recorded = set(rec.sequence[keep].tolist())
        lost = sum(g['lost'] for g in rec.gaps if since < g['received'] <= end
                   and (not g['stamp_ns'] or g['stamp_ns'] >= (t_wall - 0.5) * 1e9))
        state.update(recorded=recorded, lost=lost, missing=set(range(since, end)) - recorded,
                     gaps=[g for g in rec.gaps if since < g['received'] <= end])
        return len(state['missing']) == state['lost']
    assert op.wait_for(read, 10.0, period=0.5), \
        (f"{len(state['missing'])} samples neither recorded nor counted lost ({state['lost']} counted): "
         f"{sorted(state['missing'])[:5]}..{sorted(state['missing'])[-5:]}")
    assert set(seq_op.tolist()) <= state['recorded'] | state['missing']
    op.gap_events = state['gaps']   # for the callers' messages
    return len(state['recorded']), state['lost'], end - since


def wait_at_rest(op, timeout=10.0, hold_ok=False):
    """(b) the rig stops moving: idle/fault (or holding if allowed), not ramping, the applied command settled."""
    # holding without a stream owner: the controller holds the program's last setpoint (a completed program)
    states = (RigStatus.STATE_IDLE, RigStatus.STATE_FAULT, RigStatus.STATE_HOLDING)
    ok = op.wait_status(lambda s: s.state in states and (not s.stream_owner or hold_ok), timeout)
    assert ok, f'rig not at rest: {op.status.state_name}, {op.status.last_event}'
    # and every sample up to the rest has arrived (the last partial batch follows max_batch_delay later)
    assert op.wait_for(lambda: op.last_sequence >= op.status.last_sample, 5.0), \
        (op.last_sequence, op.status.last_sample)
    return op.status


def next_program_completes(op, procs, program=SHORT):
    """(d) reset if faulted (the operator's acknowledgement, not a lifecycle cycle), then a program runs. A reset
    refused because the rig still moves (its ramp, or a controller that has not yet reported its rest after a
    silence: the driver goes by the last state it reported) is tried again after a wait, as an operator would.
    """
    for _ in range(10):   # acknowledge until the cause is gone (a fault still present trips again at once)
        if op.status.state != RigStatus.STATE_FAULT:
            break
        r = op.trigger('rig_driver/reset')
        assert r is not None and (r.success or 'moving' in r.message or 'ramping' in r.message), r
        op.wait_ready(2.0)
    assert op.wait_ready(20.0), (op.status.state_name, op.status.fault_messages)
    since = op.last_sequence + 1
    result = op.run(program, timeout=60.0)
    assert result is not None and result.success, (result.message if result else 'no result',
                                                   procs.log('excitation')[-1500:])
    assert_applied_safe(op, since)
    for name in ('rig_driver', 'excitation', 'element_model', 'recorder'):
        assert procs.alive(name), f'{name} died:\n' + procs.log(name)[-2000:]
    return result


def goal_ends_within(op, handle, t_event, limit=1.0):
    """(c) the goal ended with a reason, at most `limit` seconds after the event."""
    result = op.result(handle, limit + 2.0)
    assert result is not None, 'goal did not end'
    elapsed = time.monotonic() - t_event
    assert not result.success and result.message, result
    assert elapsed <= limit + 0.3, f'goal ended {elapsed:.2f} s after the event'   # + result delivery
    return result


def start_fast_sine(op, seconds=1.0):
    handle = op.send_goal(FAST_SINE)
    assert handle is not None and handle.accepted
    if not op.wait_status(lambda s: s.stream_owner == f'{NS}/excitation', 10.0):
        result = op.result(handle, 1.0)
        raise AssertionError(f'program did not start: {result.message if result else "no result"}')
    first = op.status.last_sample + 1      # the program's first sample comes after every sample so far
    wait_for(lambda: op.last_sequence > first + seconds * FS, seconds + 10.0,
             f'{seconds:g} s of samples of the running program to arrive')
    return handle


def ramp_latency_samples(op, t_request_seq):
    """Samples from the request (the latest sample seen when it was sent) until the applied command leaves the
    program: the first sample whose command differs from the 14 Hz sine by more than 1 um."""
    seq, u, _ = op.applied(t_request_seq - 200)
    return seq, u


# -- the scenarios -------------------------------------------------------------------------------------------
def test_happy_path_records_every_sample(suite):
    procs, op, base = suite
    since, t_wall = op.last_sequence + 1, time.time()
    result = op.run(SHORT)
    assert result is not None and result.success, result
    seq, _ = assert_applied_safe(op, since)
    assert np.all(np.diff(seq) == 1)
    recorded, lost, judged = assert_recorded(op, base, since, t_wall)
    assert lost == 0 and recorded == judged and judged >= seq.size, (recorded, lost, judged, seq.size)
    # a setpoint batch is stamped with the rig time it is for: the time of the sample it is applied to
    sample_t = {}
    for b in op.batches:
        t0 = b.header.stamp.sec + b.header.stamp.nanosec * 1e-9
        for i in range(len(b.setpoint)):
            sample_t[b.first_sequence + i] = t0 + i * b.sample_period
    offsets = [b.header.stamp.sec + b.header.stamp.nanosec * 1e-9 - sample_t[b.first_sequence]
               for b in op.setpoints_seen if b.first_sequence >= since and b.first_sequence in sample_t]
    assert len(offsets) >= 20, f'{len(offsets)} setpoint batches of the program'
    print(f'setpoint stamp - sample time: {np.min(offsets) * 1e3:.2f} .. {np.max(offsets) * 1e3:.2f} ms')
    # estimated from the latest sample batch's stamp (before the first sample: from when the stream opened, 17 ms
    # early here): off by the bus timestamps' jitter, the stream's start-up and how late the excitation's executor
    # ran (69 ms seen with a load of 8 on two cores), never by the 0.7 s lead the batch was sent ahead
    assert np.max(np.abs(offsets)) < 0.25, offsets


@system
def test_driver_abort_mid_goal_ends_goal_and_ramps_inside_limits(suite):
    procs, op, base = suite
    since = op.last_sequence + 1
    t_wall = time.time()
    handle = start_fast_sine(op)
    t = time.monotonic()
    r = op.trigger('rig_driver/abort')
    assert r is not None and r.success
    result = goal_ends_within(op, handle, t)
    assert 'abort' in result.message, result.message
    st = wait_at_rest(op)
    assert st.state == RigStatus.STATE_IDLE and 'at rest' in st.last_event
    seq, u = assert_applied_safe(op, since)
    assert abs(u[-1]) < 1e-9                                   # ramped to the rest position
    assert_recorded(op, base, since, t_wall)                   # the ramp tail too
    next_program_completes(op, procs)


@system
@pytest.mark.parametrize('how', ['abort', 'cancel'])
def test_excitation_abort_and_cancel_act_at_once(suite, how):
    procs, op, base = suite
    since = op.last_sequence + 1
    handle = start_fast_sine(op)
    t = time.monotonic()
    if how == 'abort':
        r = op.trigger('excitation/abort')
        assert r is not None and r.success, r
    else:
        assert op.cancel(handle)
    result = op.result(handle, 3.0)
    assert result is not None and time.monotonic() - t < 1.3
    # at rest long before the 0.5 s of queued setpoints would have run out (the old path took 0.5 s + ramp)
    assert op.wait_status(lambda s: s.state == RigStatus.STATE_IDLE and not s.stream_owner, 2.0)
    t_rest = time.monotonic() - t
    assert t_rest < 0.6, f'at rest only {t_rest:.2f} s after {how}'
    assert_applied_safe(op, since)
    next_program_completes(op, procs)


@system
def test_hold_and_resume(suite):
    procs, op, base = suite
    since = op.last_sequence + 1
    handle = op.send_goal(SHORT.replace('cycles: 5', 'cycles: 15'))
    assert handle is not None and handle.accepted
    wait_for(lambda: op.last_sequence > since + 1200, 10.0, '1.2 s of samples of the program before holding it')
    r = op.hold(True)
    assert r is not None and r.success, r
    assert op.wait_status(lambda s: s.state in (RigStatus.STATE_IDLE, RigStatus.STATE_HOLDING)
                          and s.stream_owner == f'{NS}/excitation', 2.0), op.status.state_name
    assert abs(op.status.position) < 1e-6                       # the block mean
    r = op.hold(False)
    assert r is not None and r.success, r
    result = op.result(handle, 30.0)
    assert result is not None and result.success, result
    assert_applied_safe(op, since)


@system
def test_a_stopped_excitation_that_holds_the_rig_loses_its_stream_to_the_owner_watch(suite):
    """The excitation holds the rig (no setpoints flow) and then stops (SIGSTOP: alive, silent, as a node stuck
    in DDS would be): rig_driver sees its owner's heartbeat stop and treats it as stream loss within
    owner_timeout (1.5 s): fault, ramp to rest, owner released. The excitation, continued, ends the goal.
    """
    procs, op, base = suite
    since = op.last_sequence + 1
    handle = op.send_goal(SHORT.replace('cycles: 5', 'cycles: 15'))
    wait_for(lambda: op.last_sequence > since + 800, 10.0, 'samples of the program before holding it')
    assert op.hold(True).success
    assert op.wait_status(lambda s: s.state in (RigStatus.STATE_IDLE, RigStatus.STATE_HOLDING), 2.0)
    pid = procs.procs['excitation'].pid
    os.kill(pid, signal.SIGSTOP)
    t0 = time.monotonic()
    try:
        assert op.wait_status(lambda s: s.faults & RigStatus.FAULT_STREAM, 3.0), op.status.fault_messages
        took = time.monotonic() - t0
        print(f'stopped owner: stream lost {took:.2f} s after SIGSTOP')
        assert took < OWNER_TIMEOUT + 0.25 + 0.3, took    # owner_timeout + one beat + a status period and delivery
        assert any('silent for' in m and 'excitation' in m for m in op.status.fault_messages), \
            op.status.fault_messages
        st = wait_at_rest(op)
        assert not st.stream_owner
    finally:
        os.kill(pid, signal.SIGCONT)
    result = op.result(handle, 10.0)
    assert result is not None and not result.success and 'silent' in result.message, result
    assert_applied_safe(op, since)
    next_program_completes(op, procs)


@system
def test_a_stopped_element_model_is_named_within_a_second_and_in_the_result(suite):
    procs, op, base = suite
    handle = op.send_goal(SHORT.replace('cycles: 5', 'cycles: 15'))
    assert op.wait_status(lambda s: s.stream_owner == f'{NS}/excitation', 10.0)
    pid = procs.procs['element_model'].pid
    mark = len(procs.log('excitation'))
    os.kill(pid, signal.SIGSTOP)
    t0 = time.monotonic()
    try:
        assert op.wait_for(lambda: f'{NS}/element_model is silent' in procs.log('excitation')[mark:], 3.0)
        took = time.monotonic() - t0
        print(f'stopped element_model named by the excitation {took:.2f} s after SIGSTOP')
        assert took < 1.0, took
        time.sleep(0.5)
    finally:
        os.kill(pid, signal.SIGCONT)
    result = op.result(handle, 30.0)
    assert result is not None and result.success, result    # the model is no safety peer: the program runs on
    assert f'silent during the program: {NS}/element_model up to' in result.message, result.message
    assert op.wait_for(lambda: f'{NS}/element_model beats again' in procs.log('excitation')[mark:], 3.0)


@system
def test_excitation_killed_mid_program_stream_loss_ramps_to_rest(suite):
    procs, op, base = suite
    since, t_wall = op.last_sequence + 1, time.time()
    start_fast_sine(op)
    t = time.monotonic()
    procs.kill('excitation', signal.SIGKILL)
    assert op.wait_status(lambda s: s.state == RigStatus.STATE_FAULT and s.faults & RigStatus.FAULT_STREAM, 2.0)
    detected = time.monotonic() - t
    assert detected < LEAD_TIME - STREAM_TIMEOUT + 0.5, detected    # the queue runs short (+ status delivery)
    st = wait_at_rest(op)
    assert any('stream lost' in m for m in st.fault_messages), st.fault_messages
    seq, u = assert_applied_safe(op, since)
    assert abs(u[-1]) < 1e-9
    assert_recorded(op, base, since, t_wall)
    procs.start('excitation')
    assert procs.wait_started('excitation'), procs.log('excitation')[-2000:]
    next_program_completes(op, procs)


def test_rig_driver_killed_mid_program_ends_the_goal_and_a_restarted_driver_runs_the_next(suite):
    """The driver process dies (SIGKILL): the goal ends with a reason within status_timeout (0.8 s), the
    excitation keeps running, and a restarted driver (the same launch command) runs the next program."""
    procs, op, base = suite
    handle = start_fast_sine(op)
    t = time.monotonic()
    procs.kill('rig_driver', signal.SIGKILL)
    result = goal_ends_within(op, handle, t, limit=0.8 + 0.3)
    assert 'silent' in result.message and 'rig_driver' in result.message, result.message
    assert procs.alive('excitation')
    op.clear_history()                       # the restarted rig numbers its samples from 0 again
    procs.start('rig_driver')
    assert procs.wait_started('rig_driver'), procs.log('rig_driver')[-2000:]
    wait_for(lambda: op.status is not None and op.status.samples_received == 0
             and op.status.state == RigStatus.STATE_IDLE, 60.0, 'the status of the restarted driver, idle')
    next_program_completes(op, procs)


@system
def test_second_excitation_cannot_take_the_rig(suite):
    """A second excitation (another station's, misconfigured to command this rig: its own namespace, the rig's
    topics and driver) gets its goal refused with the owner's name while a program runs."""
    procs, op, base = suite
    # the other station would run on its own computer: here it shares two cores, so it runs at a lower priority
    other = SuiteProcesses(CONFIG, '/fm_b', domain_id(), base / 'logs_b',
                           {'excitation': {'amplitude_control': False, 'rig_driver': f'{NS}/rig_driver'}},
                           niceness=10)
    other.extra_args['excitation'] = ['-r', f'status:={NS}/status', '-r', f'samples:={NS}/samples',
                                      '-r', f'setpoints:={NS}/setpoints']
    with other:
        other.start('excitation')
        assert other.wait_started('excitation'), other.log('excitation')[-2000:]
        handle = start_fast_sine(op, 0.3)
        h2 = op.send_goal(SHORT, action='/fm_b/run_program', timeout=20.0)
        assert h2 is not None and h2.accepted
        res = op.result(h2, 5.0)
        assert res is not None and not res.success
        assert f'streaming for {NS}/excitation' in res.message, res.message
        assert op.status.stream_owner == f'{NS}/excitation'          # the program runs on
        r = op.trigger('excitation/abort')
        assert r.success
        op.result(handle, 3.0)
        wait_at_rest(op)
        # once the rig is free, the second station may run a program: ownership is per stream, not per node
        result = op.result(op.send_goal(SHORT, action='/fm_b/run_program', timeout=20.0), 30.0)
        assert result is not None and result.success, result
        wait_at_rest(op)
    next_program_completes(op, procs)


@system
def test_foreign_setpoints_are_refused(suite):
    procs, op, base = suite
    since = op.last_sequence + 1
    refused0 = op.status.setpoints_refused
    handle = start_fast_sine(op, 0.5)
    sid = op.status.stream_id
    head = op.status.next_sequence
    # ahead of the program (the old driver reset its stream for this), with a ramp to 3 mm
    op.publish_setpoints(head + 2000, np.linspace(0.0, 3e-3, 200))
    # contiguous-looking, with the stream id copied from status but another sender
    op.publish_setpoints(head, np.full(100, 2.4e-3), stream_id=sid)
    # the owner's own name spoofed, with a wrong stream id
    op.publish_setpoints(head, np.full(100, 2.4e-3), stream_id=sid + 1, source=f'{NS}/excitation')
    assert op.wait_status(lambda s: s.setpoints_refused >= refused0 + 400, 3.0), op.status.setpoints_refused
    r = op.trigger('excitation/abort')
    assert r.success
    result = op.result(handle, 3.0)
    assert 'operator abort' in result.message            # the program ran until the operator stopped it
    wait_at_rest(op)
    assert_applied_safe(op, since)
    next_program_completes(op, procs)


def cpu_seconds(procs) -> dict:
    """CPU time [s] each node process has used so far (user + system, /proc/<pid>/stat)."""
    out = {}
    for name, p in procs.procs.items():
        fields = Path(f'/proc/{p.pid}/stat').read_text().split()
        out[name] = (int(fields[13]) + int(fields[14])) / os.sysconf('SC_CLK_TCK')
    return out


@system
@pytest.mark.parametrize('topic', ['setpoints', 'command'])
def test_a_flood_of_foreign_setpoints_is_not_fatal(suite, topic):
    """2000 foreign batches (stream id 0, 100 setpoints each, as fast as one process publishes them) while a
    program runs, on the public `setpoints` topic (which the driver does not read) or on a command channel of the
    flooding node's own (refused and counted until the driver mutes the channel): the program runs on until the
    operator stops it."""
    procs, op, base = suite
    since = op.last_sequence + 1
    refused0 = op.status.setpoints_refused
    handle = start_fast_sine(op, 0.5)
    head = op.status.next_sequence
    c0 = cpu_seconds(procs)
    t = time.monotonic()
    for k in range(2000):
        op.publish_setpoints(head + 100 * k, np.full(100, 2.4e-3), topic=topic)
    flood_s = time.monotonic() - t
    time.sleep(1.0)
    c1 = cpu_seconds(procs)
    print('CPU s', {n: round(c1[n] - c0[n], 2) for n in c0})   # what the flood cost each node
    refused = op.status.setpoints_refused - refused0
    print(f'flood of 2000 batches on {topic} published in {flood_s:.2f} s; refused {refused} setpoints')
    assert op.status.stream_owner == f'{NS}/excitation', (op.status.state_name, list(op.status.fault_messages))
    if topic == 'command':
        # refused and counted until the channel is muted (more than 200 batches within 1 s), then dropped by DDS
        assert 100 * 200 <= refused < 100 * 2000, refused
        assert 'is muted for 10 s' in procs.log('rig_driver'), procs.log('rig_driver')[-1500:]
    else:
        assert refused == 0, refused
    r = op.trigger('excitation/abort')
    assert r.success
    result = op.result(handle, 3.0)
    assert 'operator abort' in result.message, result.message   # the program ran until the operator stopped it
    wait_at_rest(op)
    assert_applied_safe(op, since)
    next_program_completes(op, procs)


BAD_PROGRAMS = {
    'cycles_inf': 'blocks:\n  - {waveform: sine, frequency: 1 Hz, amplitude: 0.1 mm, cycles: .inf}\n',
    'cycles_1e8': 'blocks:\n  - {waveform: sine, frequency: 1 Hz, amplitude: 0.1 mm, cycles: 100000000}\n',
    'frequency_1e-9': 'blocks:\n  - {waveform: sine, frequency: 1e-9 Hz, amplitude: 0.1 mm, cycles: 1}\n',
    'sweep_1e12_s': 'blocks:\n  - {waveform: sweep_lin, frequency: 1 Hz, frequency_end: 2 Hz, amplitude: 0.1 mm, '
                    'duration: 1e12 s}\n',
    'alias_990Hz': 'blocks:\n  - {waveform: sine, frequency: 990 Hz, amplitude: 0.001 mm, cycles: 10}\n',
    'over_limit': 'blocks:\n  - {waveform: sine, frequency: 1 Hz, amplitude: 3 mm, cycles: 1}\n',
    'not_yaml': 'blocks: [\n',
}


@system
@pytest.mark.parametrize('name', sorted(BAD_PROGRAMS))
def test_bad_programs_are_refused_with_a_reason_and_nothing_moves(suite, name):
    procs, op, base = suite
    text = BAD_PROGRAMS[name]
    t = time.monotonic()
    r = op.call('excitation/load_program', LoadProgram, LoadProgram.Request(program_yaml=text), 10.0)
    assert r is not None and not r.success and r.message, r
    assert time.monotonic() - t < 2.0
    before = op.last_sequence
    _, u_before, _ = op.applied(before)
    handle = op.send_goal(text)
    result = op.result(handle, 5.0)
    assert result is not None and not result.success and result.message
    assert op.status.state in (RigStatus.STATE_IDLE, RigStatus.STATE_HOLDING) and not op.status.stream_owner
    _, u, _ = op.applied(before)                       # nothing moved (a holding rig goes on sampling)
    assert np.all(u == u_before[-1]) if u_before.size else u.size == 0
    assert procs.alive('excitation')


@system
def test_nan_batches_and_bad_parameters_do_not_take_nodes_down(suite):
    procs, op, base = suite
    from msg_defs.msg import RigSampleBatch
    pub = op.node.create_publisher(RigSampleBatch, 'samples', 10)
    bad = RigSampleBatch(first_sequence=op.last_sequence + 1, sample_period=1e-3,
                         displacement=[math.nan] * 50, force=[math.nan] * 50, setpoint=[math.nan] * 50)
    wait_for(lambda: pub.get_subscription_count() >= 3, 5.0,
             'three of the nodes to subscribe to the test\'s samples publisher')
    pub.publish(op.sign(bad, SAMPLES))   # from the rig's own driver (signed): bad data, not a forgery
    r = op.call('element_model/set_parameters', SetParameters, SetParameters.Request(parameters=[ParameterMsg(
        name='parameter_set', value=ParameterValue(type=ParameterType.PARAMETER_STRING,
                                                   string_value='/nonexistent.yaml:fit_20C'))]))
    assert r is not None and not r.results[0].successful and 'parameter_set' in r.results[0].reason
    # ros2 param set sends an integer for 50000: the driver takes it for the double force limit
    r = op.call('rig_driver/set_parameters', SetParameters, SetParameters.Request(parameters=[ParameterMsg(
        name='limits.force_max', value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=50000))]))
    assert r is not None and r.results[0].successful, r.results[0].reason
    assert op.wait_status(lambda s: s.limits.force_max == 50000.0, 2.0)
    r = op.call('rig_driver/set_parameters', SetParameters, SetParameters.Request(parameters=[ParameterMsg(
        name='sample_rate', value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=2000.0))]))
    assert r is not None and not r.results[0].successful and 'configure' in r.results[0].reason
    op.clear_history()   # the NaN batch this test published is not the rig's history
    next_program_completes(op, procs)


@system
def test_limits_tightened_at_run_time_apply_at_once(suite):
    procs, op, base = suite
    handle = start_fast_sine(op, 0.5)
    t = time.monotonic()
    r = op.call('rig_driver/set_parameters', SetParameters, SetParameters.Request(parameters=[ParameterMsg(
        name='limits.displacement_max', value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                             double_value=1.0e-3))]))
    assert r is not None and r.results[0].successful
    result = goal_ends_within(op, handle, t)
    assert 'limit' in result.message, result.message
    wait_at_rest(op)
    seq, u, _ = op.applied(op.last_sequence - 100)
    assert u[-1] <= 1.0e-3 + 1e-9                                # at rest inside the new limit
    # a program beyond the new limit is refused before anything moves; back to the old limits, it runs
    assert op.trigger('rig_driver/reset').success
    handle = op.send_goal(FAST_SINE)
    res = op.result(handle, 5.0)
    assert not res.success and 'limit' in res.message, res.message
    r = op.call('rig_driver/set_parameters', SetParameters, SetParameters.Request(parameters=[ParameterMsg(
        name='limits.displacement_max', value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                             double_value=D_MAX))]))
    assert r.results[0].successful
    next_program_completes(op, procs)


@system
def test_deactivate_activate_and_reset_then_next_program_runs(suite):
    procs, op, base = suite
    handle = start_fast_sine(op, 0.3)
    t = time.monotonic()
    r = op.call('rig_driver/change_state', ChangeState,
                ChangeState.Request(transition=Transition(id=Transition.TRANSITION_DEACTIVATE)))
    assert r is not None and r.success
    goal_ends_within(op, handle, t)
    r = op.call('rig_driver/change_state', ChangeState,
                ChangeState.Request(transition=Transition(id=Transition.TRANSITION_ACTIVATE)))
    assert r is not None and r.success
    next_program_completes(op, procs)     # no 'samples lost' / 'bad frames' fault after re-activation


def test_element_model_and_recorder_killed_and_restarted(suite):
    procs, op, base = suite
    since = op.last_sequence + 1
    handle = op.send_goal(SHORT.replace('cycles: 5', 'cycles: 10'))
    wait_for(lambda: op.last_sequence > since + 300, 10.0, '0.3 s of samples of the program before the kill')
    procs.kill('element_model', signal.SIGKILL)
    procs.start('element_model')
    assert procs.wait_started('element_model'), procs.log('element_model')[-2000:]
    result = op.result(handle, 30.0)
    assert result is not None and result.success, result      # the model is not needed to move the rig
    # the recorder dies mid-program: with require_recording the program stops (ramp), the loss is reported
    handle = start_fast_sine(op, 0.3)
    t = time.monotonic()
    procs.kill('recorder', signal.SIGKILL)
    result = goal_ends_within(op, handle, t, limit=2.5)      # recorder_timeout 2 s: its status stops
    assert 'record' in result.message, result.message
    wait_at_rest(op)
    procs.start('recorder')
    assert procs.wait_started('recorder'), procs.log('recorder')[-2000:]
    wait_for(lambda: op.recorder is not None and op.recorder.state == RecorderStatus.STATE_RECORDING
             and f'{NS}/samples' in op.recorder.topics, 30.0, 'the restarted recorder to record the samples')
    next_program_completes(op, procs)
    files = sorted((base / 'recordings').rglob('*.mcap'))
    rec = load_recording(files[0].parent, allow_truncated=True) if files else None
    assert rec is not None and rec.tail_unaccounted, 'the killed recording must say its tail is unaccounted'


@system
def test_recorder_that_cannot_write_stops_programs_before_motion(suite):
    procs, op, base = suite
    blocker = base / 'not_a_directory'
    blocker.write_text('a file where the recorder wants a directory')
    procs.start('recorder', {'output_dir': str(blocker / 'recordings')})
    assert procs.wait_started('recorder'), procs.log('recorder')[-2000:]
    wait_for(lambda: op.recorder is not None and op.recorder.state == RecorderStatus.STATE_ERROR, 30.0,
             'the recorder to report the unwritable output_dir as an error')
    assert 'not_a_directory' in op.recorder.error, op.recorder.error
    before = op.last_sequence
    _, u_before, _ = op.applied(before)
    handle = op.send_goal(SHORT)
    result = op.result(handle, 5.0)
    assert not result.success and 'record' in result.message, result.message
    _, u, _ = op.applied(before)                       # nothing moved (a holding rig goes on sampling)
    assert np.all(u == u_before[-1]) and not op.status.stream_owner
    procs.start('recorder')
    assert procs.wait_started('recorder'), procs.log('recorder')[-2000:]
    wait_for(lambda: op.recorder is not None and op.recorder.state == RecorderStatus.STATE_RECORDING
             and f'{NS}/samples' in op.recorder.topics, 30.0, 'the restarted recorder to record the samples')
    next_program_completes(op, procs)


SIM_FAULTS = {
    # name: (fault at rig time 1.2 s after the driver (re)start, program, fault bit). Each lasts long enough to
    # be detected and is over by the time the rig has ramped down, so the next program runs on the same rig.
    'silent_controller_fast': ({'type': 'silent_controller', 'duration': 0.35}, FAST_SINE, RigStatus.FAULT_WATCHDOG),
    'stuck_displacement_slow': ({'type': 'stuck_sensor', 'sensor': 'displacement', 'duration': 0.4}, SLOW_TRIANGLE,
                                RigStatus.FAULT_SENSOR),
    'stuck_force_small': ({'type': 'stuck_sensor', 'sensor': 'force', 'duration': 0.2},
                          'blocks:\n  - {waveform: sine, frequency: 2 Hz, amplitude: 0.01 mm, cycles: 20}\n',
                          RigStatus.FAULT_SENSOR),
    'corrupt_frames_fast': ({'type': 'corrupt', 'duration': 0.2, 'probability': 0.5}, FAST_SINE,
                            RigStatus.FAULT_BUS),
}


@system
@pytest.mark.parametrize('name', sorted(SIM_FAULTS))
def test_simulated_rig_faults_end_safely(suite, name):
    procs, op, base = suite
    spec, program, bit = SIM_FAULTS[name]
    fault = '[{' + ', '.join(f'{k}: {v}' for k, v in dict(spec, start=1.2).items()) + '}]'
    procs.stop('rig_driver')
    op.clear_history()                       # the restarted rig numbers its samples from 0 again
    procs.start('rig_driver', {'sim': {'faults': fault}})
    assert procs.wait_started('rig_driver'), procs.log('rig_driver')[-2000:]
    wait_for(lambda: op.status is not None and op.status.samples_received == 0
             and op.status.state == RigStatus.STATE_IDLE, 60.0, 'the status of the restarted driver, idle')
    assert op.wait_ready(60.0)
    # batches of the stopped driver still in flight when the history was cleared number their samples like the
    # new one (both count from 0): clear again now that only the new driver publishes
    op.clear_history()
    since, t_wall = op.last_sequence + 1, time.time()
    handle = op.send_goal(program)
    result = op.result(handle, 40.0)
    assert result is not None and not result.success and 'fault' in result.message, result
    st = wait_at_rest(op)
    assert st.faults & bit, (st.faults, st.fault_messages)
    assert_applied_safe(op, since)
    recorded, lost, _ = assert_recorded(op, base, stream_start(op, since), t_wall)
    if name.startswith('corrupt'):   # frames lost on the bus: recorded as lost, exactly the driver's count
        assert lost > 0 and lost == op.status.frames_lost, (lost, op.status.frames_lost, op.gap_events)
    else:
        assert lost == op.status.frames_lost, (lost, op.status.frames_lost, [str(e) for e in op.gap_events[:6]])
    next_program_completes(op, procs)        # the same driver, after the operator's reset
