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

"""The niceness of the rig_driver and excitation processes (rubber_rig/rig/priority.py, parameter ``nice``): every
thread of the process gets it, those the middleware started before the node read its parameters included.
"""
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from rubber_rig.rig.priority import set_process_nice

REPO = Path(__file__).resolve().parents[1]


def _thread_nices(pid: int) -> list:
    """The niceness of every thread of process `pid` (field 19 of /proc/<pid>/task/<tid>/stat)."""
    out = []
    for tid in os.listdir(f'/proc/{pid}/task'):
        stat = Path(f'/proc/{pid}/task/{tid}/stat').read_text()
        out.append(int(stat.rsplit(')', 1)[1].split()[16]))
    return out


def test_every_thread_of_the_process_and_of_its_children_gets_the_niceness_and_new_threads_inherit_it():
    code = ('import threading, time, os\n'
            'from rubber_rig.rig.priority import set_process_nice\n'
            'import subprocess, sys\n'
            'child = subprocess.Popen([sys.executable, \'-c\', \'import time; time.sleep(5)\'])\n'
            'ev = threading.Event()\n'
            'before = [threading.Thread(target=ev.wait) for _ in range(3)]\n'
            '[t.start() for t in before]\n'
            'print(repr(set_process_nice(7)))\n'
            'after = threading.Thread(target=ev.wait); after.start()\n'
            'print(os.getpid(), child.pid, flush=True)\n'
            'time.sleep(3); ev.set()\n')
    proc = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, text=True, cwd=REPO)
    try:
        assert proc.stdout.readline().strip() == "''"
        pid, child = map(int, proc.stdout.readline().split())
        nices = _thread_nices(pid)
        assert len(nices) == 5 and set(nices) == {7}, nices
        assert set(_thread_nices(child)) == {7}      # a process it had started (the spawned simulated rig)
    finally:
        proc.wait(10)


def test_a_niceness_outside_the_range_is_refused_and_one_not_permitted_says_why():
    with pytest.raises(ValueError, match='outside -20..19'):
        set_process_nice(-21)
    if os.geteuid() != 0:
        why = set_process_nice(os.getpriority(os.PRIO_PROCESS, 0) - 1)
    else:   # root may raise the priority: the refusal is checked in a child that drops to the user nobody
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:
            try:
                os.setgid(65534)
                os.setuid(65534)
                os.write(write, set_process_nice(os.getpriority(os.PRIO_PROCESS, 0) - 1).encode())
            finally:
                os._exit(0)
        os.close(write)
        with os.fdopen(read) as f:
            why = f.read()
        os.waitpid(pid, 0)
    assert 'CAP_SYS_NICE' in why and 'the process keeps' in why, why


@pytest.mark.ros
@pytest.mark.parametrize('node, extra', [('rig_driver', ['-p', 'autostart:=false']), ('excitation', [])])
def test_a_node_started_as_a_process_runs_at_the_niceness_of_its_parameter(tmp_path, node, extra):
    # the two nodes on the setpoint path: rig_driver feeds the controller, the excitation streams lead_time ahead
    env = dict(os.environ, ROS_DOMAIN_ID=str(170 + os.getpid() % 10), PYTHONUNBUFFERED='1')
    log = tmp_path / f'{node}.log'
    with open(log, 'wb') as out:
        proc = subprocess.Popen([sys.executable, '-m', f'rubber_rig.nodes.{node}_node', '--ros-args',
                                 '-r', '__ns:=/nice_test', '-p', 'nice:=4', *extra],
                                env=env, stdout=out, stderr=subprocess.STDOUT, cwd=REPO)
    try:
        deadline = time.monotonic() + 60.0
        while 'ready (pid' not in log.read_text() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert 'ready (pid' in log.read_text(), log.read_text()[-2000:]
        nices = _thread_nices(proc.pid)
        assert len(nices) > 3 and set(nices) == {4}, nices     # the DDS threads too
        assert 'process niceness 4' in log.read_text()
    finally:
        proc.terminate()
        proc.wait(20)


@pytest.mark.ros     # SuiteProcesses is what starts the suite (test_markers); here it is only asked for commands
def test_a_niced_suite_keeps_its_niceness_against_its_parameter_file(tmp_path):
    # SuiteProcesses(niceness=10) stands for a second station that would have a computer of its own: the parameter
    # file's nice (-10 rig_driver, -5 excitation) would set those two processes back above everything else
    from rubber_rig.cli.processes import SuiteProcesses
    config = REPO / 'config' / 'rig_sim.yaml'
    niced = SuiteProcesses(config, '/second', 0, tmp_path / 'niced', niceness=10)
    plain = SuiteProcesses(config, '/first', 0, tmp_path / 'plain')
    for node in ('rig_driver', 'excitation'):
        cmd = niced.command(node)
        assert cmd[-2] == '--params-file' and yaml.safe_load(Path(cmd[-1]).read_text()) == {
            '/**': {'ros__parameters': {'nice': 10}}}
        assert cmd.count('--params-file') == 1 + 1 and plain.command(node).count('--params-file') == 1
    assert niced.command('recorder').count('--params-file') == 1     # declares no nice: nothing to override
