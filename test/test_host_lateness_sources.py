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

"""The sources of this host's lateness in a conformance run (docs/protocol.md, "Host timing"), on synthetic data:
the kernel's run-queue waits of the simulator's process (kernel_counts), the CPU pressure reported with the run, and
the simulator's own record of its missed deadlines (sim.timing_log). Nothing here depends on how busy this host is.
"""
import os
import socket

import can
import pytest

from rubber_rig.rig.can.udp_socket import dropped, enlarge_receive_buffer, socket_inode
from rubber_rig.rig.conformance.active_stream import _judge_buffer, _sent_after_its_tick
from rubber_rig.rig.conformance.envelope import Envelope, Sample
from rubber_rig.rig.conformance.host_timing import SIM_LATE_MIN, DropWatch, HostTiming, late_total
from rubber_rig.rig.conformance.kernel_counts import (
    RUN_QUEUE_MIN,
    RunQueueWatch,
    cpu_pressure,
    pressure_share,
    read_waits,
)
from rubber_rig.rig.conformance.link import ConformanceLink
from rubber_rig.rig.conformance.report import FAIL, NOT_TESTED, PASS
from rubber_rig.rig.sim.lateness import LatenessLog


def test_a_run_queue_wait_becomes_a_window_ending_at_the_sample():
    watch = RunQueueWatch()
    task = (100, 100)
    assert watch.update(10.000, {task: 5.0}) == []           # first sight: the wait so far is no window
    assert watch.update(10.005, {task: 5.001}) == []          # 1 ms: below RUN_QUEUE_MIN
    # 30 ms waited within the 40 ms since the last sample: a window of 30 ms ending at this sample
    assert watch.update(10.045, {task: 5.031}) == [(pytest.approx(10.015), 10.045)]
    # more wait than the interval (a task of several threads is counted per thread): clipped to the interval
    other = (100, 101)
    watch.update(10.045, {other: 0.0})
    assert watch.update(10.050, {task: 5.031, other: 0.020}) == [(10.045, 10.050)]
    assert RUN_QUEUE_MIN == SIM_LATE_MIN


def test_run_queue_windows_explain_a_silence_of_the_simulator():
    """A 60 ms silence of the simulator's frames: the kernel counted 55 ms of waiting for a CPU in it (sampled
    every 5 ms, as the run does), so this host's lateness around the silence covers it; a silence where the
    simulator never waited is not explained.
    """
    watch, timing = RunQueueWatch(), HostTiming()
    wait = 0.0
    for k in range(40):
        t = 100.0 + 0.005 * k
        if 100.05 < t <= 100.105:
            wait += 0.005                                      # runnable, not running
        for a, b in watch.update(t, {(1, 1): wait}):
            timing.add(a, b, 'run-queue waits of the simulator')
    assert late_total(timing.windows, 100.045, 100.105) == pytest.approx(0.06, abs=0.006)
    assert late_total(timing.windows, 100.15, 100.19) == 0.0
    assert timing.sources['run-queue waits of the simulator'][0] == len(timing.windows) > 0


def test_read_waits_reads_this_process_and_skips_a_gone_one():
    waits = read_waits([os.getpid()])
    if not waits:
        pytest.skip('this kernel accounts no run-queue waits (/proc/<pid>/task/<tid>/schedstat)')
    assert all(pid == os.getpid() and w >= 0.0 for (pid, _), w in waits.items())
    assert (os.getpid(), os.getpid()) in waits                 # the main thread
    assert read_waits([2 ** 22 + 7]) == {}                     # no such process: nothing, no error


def test_cpu_pressure_parses_the_some_total_and_gives_a_share(tmp_path):
    psi = tmp_path / 'cpu'
    psi.write_text('some avg10=88.37 avg60=35.53 avg300=17.79 total=15213126470\n'
                   'full avg10=0.00 avg60=0.00 avg300=0.00 total=0\n')
    assert cpu_pressure(str(psi)) == pytest.approx(15213.126470)
    assert cpu_pressure(str(tmp_path / 'missing')) is None
    psi.write_text('garbage\n')
    assert cpu_pressure(str(psi)) is None
    assert pressure_share(100.0, 127.0, 30.0) == pytest.approx(0.9)
    assert pressure_share(100.0, 200.0, 30.0) == 1.0 and pressure_share(None, 1.0, 30.0) is None


def test_the_simulator_logs_a_late_wakeup_and_a_frame_read_late(tmp_path):
    now = 1000.0
    log = LatenessLog(wall=lambda: now)                        # the wall clock, as the simulator reads it
    log.missed(0.5)                                            # no file: nothing, no error
    path = tmp_path / 'late.txt'
    log.file = path.open('a', encoding='utf-8')
    log.woke(now - 1.0, 0.5, None)          # asked 1 s ago for at most 0.5 s: woke 0.5 s late
    msg = can.Message(arbitration_id=1, timestamp=now - 0.3)
    log.woke(now - 1.0, 0.9, msg)           # a frame that arrived 0.3 s ago, read only now
    log.woke(now - 0.001, 0.5, can.Message(arbitration_id=1, timestamp=now - 2.0))   # queued before: not a wake
    log.missed(0.001)                       # below SIM_LATE_MIN
    log.missed(0.004, noticed=now - 0.1)    # behind from 4 ms before it noticed until it caught up (now)
    log.close()
    windows = [tuple(map(float, line.split())) for line in path.read_text().splitlines()]
    assert len(windows) == 3
    assert windows == [pytest.approx((999.5, 1000.0)), pytest.approx((999.7, 1000.0)),
                       pytest.approx((999.896, 1000.0))]


def test_a_socket_drop_becomes_a_window_since_the_previous_reading(tmp_path):
    watch = DropWatch()
    assert watch.update(5.0, 3) is None                    # first reading: what was lost before is no window
    assert watch.update(5.005, 3) is None and watch.update(5.010, None) is None
    assert watch.update(5.020, 9) == (5.005, 5.020)         # lost between the last two readings
    table = tmp_path / 'udp'
    table.write_text('  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout '
                     'inode ref pointer drops\n'
                     '11886: 00000000:B26E 00000000:0000 07 00000000:00034000 00:00000000 00000000     0        0 '
                     '563271 2 0000000007555bcf 4549\n')
    assert dropped(563271, (str(table),)) == 4549
    assert dropped(1, (str(table),)) is None and dropped(None) is None


def test_the_simulator_logs_what_its_socket_dropped(tmp_path):
    now, count = 1000.0, [0]
    log = LatenessLog(wall=lambda: now, drops=lambda: count[0])
    path = tmp_path / 'late.txt'
    log.file = path.open('a', encoding='utf-8')
    log.woke(now, 0.0, None)                   # first reading
    now, count[0] = 1000.2, 40                 # 40 frames lost while it did not read its socket
    log.woke(now, 0.0, None)
    now = 1000.201
    log.woke(now, 0.0, None)                   # read again only DROPS_PERIOD later
    log.close()
    assert [tuple(map(float, line.split())) for line in path.read_text().splitlines()] == [(1000.0, 1000.2)]


def test_a_bus_socket_gets_a_deep_receive_queue_and_its_drops_are_read():
    """On a UDP socket bound to loopback (what udp_multicast's bus holds; no multicast group is joined here, so
    nothing reaches a network): the receive queue grows, the socket is found in /proc/net/udp with 0 drops.
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind(('127.0.0.1', 0))
        default = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        granted = enlarge_receive_buffer(sock, 1 << 20)
        assert granted > default and granted == sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        assert dropped(socket_inode(sock)) == 0
    finally:
        sock.close()
    assert enlarge_receive_buffer(object()) == 0 and socket_inode(object()) is None


def _buffer_run(off_at: set):
    """A link whose controller streamed 1 s (a setpoint frame of `per` setpoints every `per` ms, 30 ms ahead of
    its tick) and reported its buffer level every 10 ms, correctly except in the status frames `off_at` (indices:
    then 150 setpoints too few, as a controller that had not read its socket for 150 ms).
    """
    bus = can.Bus(interface='virtual', channel='buffer_level_attribution', receive_own_messages=False)
    link = ConformanceLink(bus, 1000.0, Envelope(-1e-3, 1e-3))
    per = link.frames.setpoints_per_frame
    link.sent_log = [(0.001 * k, 0.001 * k, 1000 + 30 + k, per) for k in range(0, 1000, per)]
    for i, k in enumerate(range(10, 1000, 10)):
        t = 0.001 * k
        sent = max(f + n for started, _, f, n in link.sent_log if started <= t)
        last = 1000 + k
        level = sent - 1 - last - (150 if i in off_at else 0)
        link.status_log.append((t, 'running', 0, last % (1 << 16), level))
    bus.shutdown()
    return link


def test_a_buffer_level_off_only_where_this_host_was_late_is_not_judged():
    off = {20, 21, 22, 50, 51, 52}           # 6 of 99 status frames: more than the 2 % a controller may be off
    link = _buffer_run(off)
    _judge_buffer(link, 0.0, 1.0)
    assert link.results['CTRL-ST-4'].status == FAIL
    link = _buffer_run(off)
    link.host_timing.add(0.09, 0.21, 'simulator')      # the simulator did not run then: it read them late
    link.host_timing.add(0.39, 0.51, 'simulator')
    _judge_buffer(link, 0.0, 1.0)
    r = link.results['CTRL-ST-4']
    assert r.status == NOT_TESTED and 'not judged: this host was late by 120 ms' in r.detail, r
    assert '6 with a level off' in r.measured
    assert '6 of them by no more than this host was late just before' in r.measured
    link = _buffer_run(off)
    link.host_timing.add(0.09, 0.21, 'simulator')      # late at one of the two places only: the other is its own
    _judge_buffer(link, 0.0, 1.0)
    assert link.results['CTRL-ST-4'].status == FAIL
    link = _buffer_run(off)
    link.host_timing.add(0.18, 0.21, 'simulator')      # late, but for 30 ms: it cannot have missed ~100 ms of them
    link.host_timing.add(0.48, 0.51, 'simulator')
    _judge_buffer(link, 0.0, 1.0)
    assert link.results['CTRL-ST-4'].status == FAIL
    link = _buffer_run(set())
    _judge_buffer(link, 0.0, 1.0)
    assert link.results['CTRL-ST-4'].status == PASS


def test_a_resumed_stream_sent_after_its_tick_is_this_hosts_lateness():
    """CTRL-STREAM-3 resumes LEAD ahead of the last sample the run saw; a run whose view lagged more than that
    sent the first setpoint after the controller had ticked past it (holding): the delay is the host's.
    """
    bus = can.Bus(interface='virtual', channel='resume_attribution', receive_own_messages=False)
    link = ConformanceLink(bus, 1000.0, Envelope(-1e-3, 1e-3))
    bus.shutdown()
    link.samples = [Sample(10.0 + 0.001 * k, 5000 + k, 0.0, 0.0, 'holding', 0.0) for k in range(400)]
    link.sent_at = {5100: 10.25}               # sequence 5100 was ticked (held) at 10.100: sent 150 ms late
    assert _sent_after_its_tick(link, 5100) == pytest.approx(0.15)
    link.sent_at = {5300: 10.25}               # in time: 50 ms before its tick
    assert _sent_after_its_tick(link, 5300) == 0.0
    assert _sent_after_its_tick(link, 9999) == 0.0      # never ticked: unknown, not excused
