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


"""rubber_rig.cpu: the CPU figures the benchmarks and `rubber-rig bench` report, checked against what the measured
process and thread say of themselves (no timing thresholds: a busy machine changes the figures, not the checks).
"""
import os
import subprocess
import sys
import threading
import time

import pytest

from rubber_rig import cpu
from rubber_rig.cli.bench_nodes import node_parameters, suite_facts
from rubber_rig.cli.processes import separate_sim_rig

from support.suite import CONFIG

BURN = """
import sys, time
while time.process_time() < 0.3:     # 0.3 s of its own CPU time, however long that takes on a busy machine
    pass
print(time.process_time(), flush=True)
sys.stdin.readline()                  # stay alive (and idle) until the test has read /proc
"""


def test_process_cpu_is_what_the_process_used():
    child = subprocess.Popen([sys.executable, '-c', BURN], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        meter = cpu.CpuMeter({'burner': child.pid}).start()   # started after the child: it counts part of the burn
        own = float(child.stdout.readline())
        measured = cpu.process_cpu(child.pid)
        report = meter.stop()
    finally:
        child.communicate('\n', timeout=30)
    # utime + stime in clock ticks (10 ms) against the child's own process_time(), read while it sits idle
    assert measured == pytest.approx(own, abs=2.5 / cpu.CLOCK_TICKS)
    use = report.processes[0]
    assert use.name == 'burner' and 0 < use.cores * report.wall_time <= measured + 1e-9
    assert report.machine_cores >= report.watched_cores - 2.0 / cpu.CLOCK_TICKS / report.wall_time
    assert report.other_cores >= 0 and report.cores >= 1
    assert cpu.process_cpu(child.pid) != cpu.process_cpu(child.pid)   # gone: NaN


def test_wake_ups_are_the_named_thread_blocking():
    done, counts = threading.Event(), {}

    def worker():
        cpu.name_this_thread(cpu.EXECUTOR_THREAD)
        counts['tid'] = threading.get_native_id()
        counts['before'] = cpu.thread_cpu_and_waits(counts['pid'], counts['tid'])[1]
        for _ in range(50):
            time.sleep(0.001)          # each sleep blocks the thread: one voluntary context switch at least
        counts['after'] = cpu.thread_cpu_and_waits(counts['pid'], counts['tid'])[1]
        done.wait(30)

    counts['pid'] = os.getpid()
    t = threading.Thread(target=worker)
    t.start()
    try:
        for _ in range(1000):
            if 'after' in counts:
                break
            time.sleep(0.01)
        assert cpu.executor_thread(os.getpid()) == counts['tid']
        assert counts['after'] - counts['before'] >= 50
    finally:
        done.set()
        t.join()


def test_report_says_when_others_used_the_machine():
    quiet = cpu.CpuReport(10.0, [cpu.ProcessUse('a', 1, 0.5, _wall=10.0)], 0.55, 2, 0.1, 0.2)
    busy = cpu.CpuReport(10.0, [cpu.ProcessUse('a', 1, 0.5, _wall=10.0)], 1.5, 2, 1.9, 2.1)
    assert not quiet.under_load and quiet.other_cores == pytest.approx(0.05)
    assert busy.under_load and busy.other_cores == pytest.approx(1.0)
    assert any('MEASURED UNDER LOAD' in line for line in busy.lines())
    assert not any('UNDER LOAD' in line for line in quiet.lines())
    assert busy.as_dict()['other_cores_used'] == pytest.approx(1.0)


def test_bench_reads_the_rig_facts_from_the_parameter_file():
    params = node_parameters(CONFIG, 'rig_driver')
    assert params['sample_rate'] == 1000.0 and params['limits.velocity_max'] == 0.2
    facts = suite_facts(CONFIG, {'sample_rate': 2000.0}, {})
    assert facts.sample_rate == 2000.0 and facts.batch_size == 20      # 10 ms of samples (batch_size 0)
    assert facts.paced and facts.backend == 'sim' and facts.specimen == 'swing_arm_joint_20C'
    assert facts.hold_timeout == node_parameters(CONFIG, 'excitation').get('hold_timeout', 600.0)
    assert suite_facts(CONFIG, {}, {'hold_timeout': 30.0}).hold_timeout == 30.0


def test_separate_sim_rigs_of_two_suites_do_not_share_a_bus():
    a, b, c = separate_sim_rig(63), separate_sim_rig(64), separate_sim_rig(63, '/rig_b')
    assert a['spawn_sim'] and a['backend'] == 'udp_multicast'
    assert len({(x['can.channel'], x['can.bus_options']) for x in (a, b, c)}) == 3
    assert len({x['can.bus_options'] for x in (a, b, c)}) == 3      # ports apart too (Linux: IP_MULTICAST_ALL)
