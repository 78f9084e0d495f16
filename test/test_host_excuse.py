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

"""A scenario's FAIL where this host was late enough to explain it is not judged (conformance/host_excuse.py,
docs/protocol.md "Host timing", issue 36 item 5), on synthetic stretches and lateness windows: a FAIL with no
lateness stays a FAIL, with lateness that explains it becomes *not judged*, with lateness too short, spread out,
elsewhere or in only one of its stretches stays a FAIL. And the measurement fixes that make an excuse unneeded:
the reference spring fitted on the samples received, the ramp judged from the last sample before its command.
"""
import math
import os
import subprocess
import sys
import threading
import time

import can
import numpy as np
import pytest

from rubber_rig.rig.conformance.active_ramps import _last_before
from rubber_rig.rig.conformance.active_stream import _judge_applied
from rubber_rig.rig.conformance.envelope import Envelope, Sample
from rubber_rig.rig.conformance.host_excuse import TIME_TOLERANCE, excuse
from rubber_rig.rig.conformance.host_timing import LATE_MIN, MARGIN, LateSpans, late_total, longest_late
from rubber_rig.rig.conformance.kernel_counts import OWN_WAITS, KernelCounts
from rubber_rig.rig.conformance.link import (
    LEAD,
    REACTION,
    SCENARIO_THREAD,
    ConformanceLink,
)
from rubber_rig.rig.conformance.reference_specimen import fit_spring
from rubber_rig.rig.conformance.report import FAIL, NOT_TESTED, PASS, Results, Stretch


def _failed(rid='CTRL-RAMP-1', stretch=None, detail='step of 0.5 mm'):
    results = Results()
    results.put(rid, FAIL, 'measured', detail, stretch or Stretch(10.0, 12.0, 's_stream'))
    return results


def test_a_fail_with_no_lateness_stays_a_fail():
    results = _failed()
    assert excuse(results, []) == []
    assert results['CTRL-RAMP-1'].status == FAIL and results['CTRL-RAMP-1'].detail == 'step of 0.5 mm'


def test_a_fail_where_this_host_was_late_longer_than_the_tolerance_is_not_judged():
    results = _failed()
    # two sources saw the same 150 ms delay (overlapping windows): one stretch of 150 ms >= REACTION (100 ms)
    windows = [(11.00, 11.12), (11.10, 11.15)]
    assert excuse(results, windows, origin=5.0) == ['CTRL-RAMP-1']
    r = results['CTRL-RAMP-1']
    assert r.status == NOT_TESTED
    assert r.detail.startswith('not judged: this host was late by 150 ms'), r.detail
    assert 's_stream 5.00-7.00 s into the run' in r.detail and 'step of 0.5 mm' in r.detail
    assert r.measured == 'measured'


def test_lateness_too_short_spread_out_or_elsewhere_leaves_the_fail():
    short = [(11.0, 11.0 + 0.8 * REACTION)]                        # 80 ms < 100 ms
    spread = [(10.2 + 0.1 * k, 10.2 + 0.1 * k + 0.05) for k in range(10)]   # 500 ms in all, never 100 ms at once
    elsewhere = [(20.0, 21.0)]                                     # a second late, 8 s after the stretch
    for windows in (short, spread, elsewhere):
        results = _failed()
        assert excuse(results, windows) == [], windows
        assert results['CTRL-RAMP-1'].status == FAIL
    assert longest_late(spread, 10.0, 12.0) == pytest.approx(0.05)


def test_a_violation_that_is_a_time_is_excused_by_all_the_lateness_at_least_its_excess():
    """A ramp 60 ms longer than its bound, where the simulator was late 10 x 8 ms (no single delay of 100 ms):
    80 ms >= 60 ms, not judged; 10 x 4 ms (40 ms) cannot explain it.
    """
    stretch = Stretch(10.0, 12.0, excess=0.06)
    results = _failed(stretch=stretch)
    assert excuse(results, [(10.1 + 0.1 * k, 10.108 + 0.1 * k) for k in range(10)]) == ['CTRL-RAMP-1']
    assert 'late by 80 ms' in results['CTRL-RAMP-1'].detail
    results = _failed(stretch=stretch)
    assert excuse(results, [(10.1 + 0.1 * k, 10.104 + 0.1 * k) for k in range(10)]) == []


def test_every_stretch_of_a_fail_must_be_explained():
    results = _failed()
    results.put('CTRL-RAMP-1', FAIL, 'second ramp', 'duration', Stretch(30.0, 32.0, 's_reset_moving'))
    late_at_first = [(11.0, 11.5)]
    assert excuse(results, late_at_first) == [] and results['CTRL-RAMP-1'].status == FAIL
    assert excuse(results, late_at_first + [(31.0, 31.2)]) == ['CTRL-RAMP-1']
    assert 's_stream 10.00-12.00 s into the run; s_reset_moving 30.00-32.00' in results['CTRL-RAMP-1'].detail


def test_a_fail_without_a_stretch_or_on_a_value_is_never_excused():
    results = Results()
    results.put('CTRL-HB-1', FAIL, 'silent for 300 ms', 'period')         # a check of the whole trace
    results.put('CTRL-MEAS-1', FAIL, 'ratio 0.001', 'kN', Stretch(10.0, 12.0))   # a value, not a time
    results.put('CTRL-RAMP-1', FAIL, 'ramp', 'step', Stretch(10.0, 12.0))
    results.put('CTRL-RAMP-1', FAIL, 'ramp', 'step')                        # judged again, no stretch
    assert 'CTRL-MEAS-1' not in TIME_TOLERANCE
    assert excuse(results, [(9.0, 13.0)]) == []
    assert {r.status for r in results.values()} == {FAIL}


def test_a_reference_motion_not_taken_while_this_host_was_late_is_not_judged():
    """CTRL-MEAS-1 is on values, never excused - but 'the controller did not take the reference motion' is a time:
    its stretch carries LEAD as its tolerance (a stream underrun by this host).
    """
    results = Results()
    results.put('CTRL-MEAS-1', FAIL, '0 samples of the reference motion received', 'not taken',
                Stretch(10.0, 12.5, 's_reference', tolerance=LEAD))
    assert excuse(results, [(11.0, 11.0 + 0.5 * LEAD)]) == []
    assert excuse(results, [(11.0, 11.0 + 1.5 * LEAD)]) == ['CTRL-MEAS-1']


def test_a_pass_is_never_touched_and_the_tolerance_is_the_requirements_own():
    results = Results()
    results.put('CTRL-LIM-1', PASS, 'upwards: stopped at the limit')
    results.put('CTRL-STREAM-3', FAIL, 'resumed 0 of 500', 'underrun', Stretch(10.0, 11.0))
    results.put('CTRL-LIM-1', FAIL, 'downwards: stopped at 0.4007 mm', 'stop', Stretch(20.0, 20.2))
    windows = [(10.5, 10.5 + 0.9 * LEAD), (20.05, 20.05 + REACTION)]   # 270 ms < LEAD; 100 ms = 100 ms
    assert excuse(results, windows) == ['CTRL-LIM-1']
    assert results['CTRL-STREAM-3'].status == FAIL
    assert results['CTRL-LIM-1'].status == NOT_TESTED and 'upwards' in results['CTRL-LIM-1'].measured


def test_what_no_delay_can_make_or_a_rule_of_its_own_decides_is_never_excused_by_a_stall():
    """A setpoint applied beyond a limit, a fault cleared without RESET (infinite tolerance), CTRL-ID-1 and
    CTRL-WD-1 (their own rules weigh the lateness against the violation): a 2 s stall leaves them failed. A ramp
    that never began within 15 s is a time: only 15 s of lateness could explain it.
    """
    results = Results()
    results.put('CTRL-LIM-2', FAIL, 'farthest applied 0.6 mm', 'beyond', Stretch(10.0, 12.0, tolerance=math.inf))
    results.put('CTRL-FAULT-2', FAIL, 'cleared after 0.5 s', 'latch', Stretch(10.0, 12.0, tolerance=math.inf))
    results.put('CTRL-ID-1', FAIL, 'answered in 900 ms', 'late', Stretch(10.0, 12.0))
    results.put('CTRL-WD-1', FAIL, 'never ramped', 'silence', Stretch(10.0, 12.0))
    never = Stretch(10.0, 25.0, excess=15.0, tolerance=math.inf)
    results.put('CTRL-RAMP-1', FAIL, 'no ramp', 'no ramp to rest', never)
    assert excuse(results, [(10.5, 12.5)]) == []
    assert {r.status for r in results.values()} == {FAIL}
    assert excuse(results, [(10.0, 25.0)]) == ['CTRL-RAMP-1']


def test_a_stretch_of_its_own_tolerance_the_stated_host_timeout():
    results = _failed('CTRL-FAULT-1', Stretch(10.0, 12.0, tolerance=1.0), 'expected exactly displacement_limit')
    assert excuse(results, [(10.5, 11.0)]) == []             # 500 ms: shorter than the stated 1 s host timeout
    assert excuse(results, [(10.5, 11.6)]) == ['CTRL-FAULT-1']


def test_a_fail_put_during_a_scenario_judged_the_scenario_so_far():
    results = Results()
    clock = {'t': 12.5}
    results.stamp = lambda: Stretch(10.0, clock['t'], 's_hold')
    results.put('CTRL-RAMP-2', FAIL, 'decel 40 m/s^2')
    results.put('CTRL-RAMP-1', FAIL, 'ramp', 'step', Stretch(11.0, 11.5))
    results.put('CTRL-RAMP-2', PASS, 'again')
    assert results.stretches['CTRL-RAMP-2'] == [Stretch(10.0, 12.5, 's_hold')]
    assert results.stretches['CTRL-RAMP-1'] == [Stretch(11.0, 11.5, 's_hold')]   # its own, named by the stamp
    results.stamp = None
    results.put('CTRL-RAMP-2', FAIL, 'from the trace')
    assert results.stretches['CTRL-RAMP-2'][-1] is None


def test_the_scenario_thread_records_its_own_late_wakeup():
    """The run's scenario thread asks for 1 ms and cannot run for ~50 ms: a thread holding the interpreter (the
    switch interval set to 50 ms) keeps it from its CPU as another process would. The delay is this host's.
    """
    bus = can.Bus(interface='virtual', channel='scenario_thread_lateness', receive_own_messages=False)
    link = ConformanceLink(bus, 1000.0, Envelope(-1e-3, 1e-3))
    bus.shutdown()
    stop, started = threading.Event(), threading.Event()

    def spin():
        started.set()
        while not stop.is_set():
            sum(range(1000))
    interval = sys.getswitchinterval()
    sys.setswitchinterval(0.05)
    worker = threading.Thread(target=spin, daemon=True)
    try:
        worker.start()
        started.wait(1.0)
        for _ in range(3):
            link._pause(0.001)
    finally:
        stop.set()
        sys.setswitchinterval(interval)
        worker.join(2.0)
    count, seconds = link.host_timing.sources[SCENARIO_THREAD]
    assert count >= 1 and seconds >= LATE_MIN
    assert all(b - a >= LATE_MIN for a, b in link.host_timing.windows)


def test_the_runs_own_process_is_watched_for_run_queue_waits():
    timing = type('Timing', (), {'added': [], 'add': lambda self, *w: self.added.append(w)})()
    counts = KernelCounts(timing, own_pid=os.getpid())
    counts.sample(1.0)
    counts.sample(1.01)
    assert {task[0] for task in counts._own._last} == {os.getpid()}
    assert all(source == OWN_WAITS for *_, source in timing.added)


def test_the_reference_spring_is_fitted_on_the_samples_received_only():
    """A 10 kN/mm spring whose force lags 0.2 samples, 2 Hz, with bursts of 200, 13 and 50 samples lost (a
    socket's queue overflowing): the fit on the samples received, whose neighbours are known by sequence, gives k
    and the 0.2 ms delay; the same samples taken as contiguous (the fit before) differentiate across the gaps and
    miss the delay by more than half of it.
    """
    fs, k, lag = 1000.0, 1e7, 0.2e-3
    seq = np.arange(2000)
    x = 0.2e-3 * np.sin(2 * math.pi * 2.0 * seq / fs)
    force = k * 0.2e-3 * np.sin(2 * math.pi * 2.0 * (seq / fs - lag)) + np.random.default_rng(1).normal(0, 0.5, 2000)
    kept = np.ones(seq.size, bool)
    kept[500:700] = kept[1200:1213] = kept[1600:1650] = False
    fit = fit_spring(x[kept], force[kept], fs, seq[kept])
    assert fit.k == pytest.approx(k, rel=1e-4) and fit.delay == pytest.approx(lag, rel=0.02)
    assert fit.n == kept.sum() - 2 - 6                   # the ends and the samples either side of each gap
    old = fit_spring(x[kept], force[kept], fs)
    assert abs(old.delay - lag) > 0.5 * lag


def test_the_ramp_starts_from_the_last_sample_that_arrived_before_the_command():
    """The run's view lagged: at the command (t = 10.3 s) it had read samples up to 10.0 s only, the others
    arrived (on the bus) before the command too. At judge time the ramp's start is the last of them.
    """
    bus = can.Bus(interface='virtual', channel='ramp_start', receive_own_messages=False)
    link = ConformanceLink(bus, 1000.0, Envelope(-1e-3, 1e-3))
    bus.shutdown()
    link.samples = [Sample(10.0 + 0.001 * k, 5000 + k, 0.0, 1e-6 * k, 'running', 0.0) for k in range(600)]
    start = _last_before(link, 10.2995, 5301)
    assert start.seq == 5299 and start.u == pytest.approx(299e-6)
    assert _last_before(link, 10.2995, 9000) is None        # a sequence far beyond: not the stream it went on from


def test_late_spans_answer_as_late_total_does_for_many_stretches_at_once():
    """A loaded run records over ten thousand windows and a periodic frame has ten thousand intervals: the union
    of the windows, queried by bisection, gives every interval's lateness as late_total does one at a time.
    """
    rng = np.random.default_rng(3)
    starts = np.sort(rng.uniform(0.0, 20.0, 2000))
    windows = [(a, a + (rng.uniform(0.002, 0.4) if k % 40 == 0 else rng.uniform(0.002, 0.02)))
               for k, a in enumerate(starts)]
    lo = rng.uniform(-1.0, 21.0, 300)
    hi = lo + rng.uniform(0.0, 0.2, 300)
    spans = LateSpans(windows)
    expected = [late_total(windows, a + MARGIN, b - MARGIN) for a, b in zip(lo, hi, strict=True)]
    assert spans.total(lo, hi) == pytest.approx(expected, abs=1e-12)
    covered = LateSpans(windows, MARGIN).covers(lo)
    assert list(covered) == [any(a - MARGIN <= x <= b + MARGIN for a, b in windows) for x in lo]
    assert LateSpans([]).total(lo, hi).tolist() == [0.0] * 300 and not LateSpans([]).covers(lo).any()


def test_a_simulator_outlives_no_run_killed_by_a_timeout():
    """A run killed (SIGKILL, as subprocess.run's timeout does) took its simulator with it: orphaned simulators
    kept loading this host for minutes after timed-out runs. The child of a process started with the run's
    preexec_fn ends when that process is killed.
    """
    parent = subprocess.Popen([sys.executable, '-c', (
        'import subprocess, sys, time\n'
        'from rubber_rig.cli.conformance import _ends_with_this_process\n'
        'p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], '
        'preexec_fn=_ends_with_this_process())\n'
        'print(p.pid, flush=True)\n'
        'time.sleep(60)\n')], stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    parent.kill()
    parent.wait()
    deadline = time.monotonic() + 10.0
    state = 'S'
    while time.monotonic() < deadline:
        try:
            with open(f'/proc/{child}/status', encoding='ascii') as f:
                state = f.read().split('State:')[1].split()[0]
        except FileNotFoundError:
            state = 'gone'
        if state in ('Z', 'X', 'gone'):
            break
        time.sleep(0.05)
    assert state in ('Z', 'X', 'gone'), state       # exited (a zombie until init reaps it), not sleeping on


def test_a_stream_this_host_sent_late_is_not_judged_and_a_wrong_setpoint_still_fails():
    """CTRL-STREAM-4 on a stream of 1000 setpoints, 100 of them sent by this host 150 ms after the controller had
    ticked them (a stall longer than LEAD): not the controller's doing, not judged; one setpoint applied with
    another value fails however late the others were.
    """
    bus = can.Bus(interface='virtual', channel='stream_sent_late', receive_own_messages=False)
    link = ConformanceLink(bus, 1000.0, Envelope(-1e-3, 1e-3))
    bus.shutdown()
    samples = [Sample(10.0 + 0.001 * k, 2000 + k, 0.0, 1e-7 * k, 'running', 0.0) for k in range(1000)]
    link.sent = {2000 + k: 1e-7 * k for k in range(1000)}
    link.sent_at = {2000 + k: 10.0 + 0.001 * k - (0.3 if k < 900 else -0.15) for k in range(1000)}
    _judge_applied(link, samples, 2000, 3000, 'stream')
    r = link.results['CTRL-STREAM-4']
    assert r.status == NOT_TESTED and 'late by 150 ms' in r.detail and '100 sent too late' in r.measured, r
    link.results.clear()
    link.sent[2500] = 5e-6                         # applied 0.05 mm, sent 5 um
    _judge_applied(link, samples, 2000, 3000, 'stream')
    assert link.results['CTRL-STREAM-4'].status == FAIL
