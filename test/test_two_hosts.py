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

"""Two computers: rig_driver (with the simulated rig it drives) on the rig PC, the excitation, the element model,
the recorder and the operator on a second one, DDS between them over a network link. The two hosts are two
private network namespaces joined by a veth pair (addresses 10.213.7.1/.2 exist only inside them: nothing leaves
this machine). A program runs across the link; the link is cut mid-program (``ip link set down``): the rig PC,
alone, ends the program at rest and says why; the link comes back, the operator resets the rig from the second
host and the next program runs. The wiring of a lab's two-PC set-up, end to end (the logic of each decision is
tested on simulated time: test_scenario*.py).
"""
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve()
CONFIG = ROOT / 'config' / 'rig_sim.yaml'
RIG_PC = 'RUBBER_RIG_TWO_HOSTS_RIG_PC'        # set to the rig PC's namespace in the run on the second host
NS = '/lab'
PROGRAM = 'name: across\nblocks:\n  - {waveform: sine, frequency: 5 Hz, amplitude: 0.5 mm, cycles: 10}\n'
LONG = 'name: long\nblocks:\n  - {waveform: sine, frequency: 5 Hz, amplitude: 0.5 mm, cycles: 100}\n'


def sh(*args, check=True):
    return subprocess.run(args, capture_output=True, text=True, timeout=30, check=check)


def make_hosts(tag: str):
    """Two named network namespaces joined by a veth pair, each with multicast routed on its link (DDS
    discovery); returns their names, or a skip reason."""
    if os.geteuid() != 0 or shutil.which('ip') is None:
        return None, 'two hosts need root and ip (iproute2) to create network namespaces joined by a veth pair'
    rig, lab = f'rr{tag}rig', f'rr{tag}lab'
    try:
        sh('ip', 'netns', 'add', rig)
        sh('ip', 'netns', 'add', lab)
        sh('ip', 'link', 'add', 'vrig', 'netns', rig, 'type', 'veth', 'peer', 'name', 'vlab', 'netns', lab)
        for host, link, addr in ((rig, 'vrig', '10.213.7.1/24'), (lab, 'vlab', '10.213.7.2/24')):
            for cmd in (('ip', 'link', 'set', 'lo', 'up'), ('ip', 'addr', 'add', addr, 'dev', link),
                        ('ip', 'link', 'set', link, 'up'), ('ip', 'route', 'add', '224.0.0.0/4', 'dev', link)):
                sh('ip', 'netns', 'exec', host, *cmd)
    except subprocess.CalledProcessError as exc:
        drop_hosts(rig, lab)
        return None, f'cannot create the two hosts: {" ".join(exc.cmd)}: {exc.stderr.strip()}'
    return (rig, lab), ''


def drop_hosts(*hosts):
    for host in hosts:
        sh('ip', 'netns', 'del', host, check=False)      # its end of the veth pair goes with it


@pytest.mark.ros
def test_two_hosts_run_a_program_survive_a_cut_link_and_run_the_next():
    if os.environ.get(RIG_PC):
        pytest.skip('the run on the second host (test_on_the_second_host)')
    hosts, why = make_hosts(str(os.getpid() % 100000))
    if hosts is None:
        pytest.skip(why)
    rig, lab = hosts
    try:
        env = dict(os.environ, **{RIG_PC: rig}, ROS_AUTOMATIC_DISCOVERY_RANGE='SUBNET')
        env.pop('FASTRTPS_DEFAULT_PROFILES_FILE', None)
        env.pop('RUBBER_RIG_DDS', None)
        inner = f'{HERE}::test_on_the_second_host'
        proc = subprocess.run(['ip', 'netns', 'exec', lab, sys.executable, '-m', 'pytest', inner, '-q', '-s', '-p',
                               'no:cacheprovider', '--timeout=240'], cwd=ROOT, env=env, capture_output=True,
                              text=True, timeout=280)
        print(proc.stdout[-6000:], proc.stderr[-2000:])
        assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-2000:]
        assert '1 passed' in proc.stdout
    finally:
        drop_hosts(rig, lab)


@pytest.mark.ros
def test_on_the_second_host(tmp_path):
    rig = os.environ.get(RIG_PC)
    if not rig:
        pytest.skip('runs on the second host of test_two_hosts_run_a_program_survive_a_cut_link_and_run_the_next')
    import socket

    from msg_defs.msg import RigStatus
    from rubber_rig.testing.operator import Operator
    from rubber_rig.testing.processes import SuiteProcesses
    assert sorted(name for _, name in socket.if_nameindex()) == ['lo', 'vlab'], 'not on the second host'
    domain = 170 + os.getpid() % 40
    procs = SuiteProcesses(CONFIG, NS, domain, tmp_path / 'logs', {'recorder': {'output_dir': str(tmp_path / 'rec')}})
    procs.prefix['rig_driver'] = ['ip', 'netns', 'exec', rig]      # the rig PC
    procs.start_all()
    op = Operator(NS, domain)
    try:
        assert op.wait_ready(90.0), 'the suite did not come up across the link:\n' + procs.log('rig_driver')[-3000:]
        first = op.run(PROGRAM, timeout=60.0)
        assert first is not None and first.success, first and first.message
        print(f'across the link: {first.message}')
        handle = op.send_goal(LONG)
        assert op.wait_status(lambda s: s.state == RigStatus.STATE_RUNNING, 10.0), 'the long program did not start'
        time.sleep(1.0)
        sh('ip', 'netns', 'exec', rig, 'ip', 'link', 'set', 'vrig', 'down')     # the cable is pulled
        cut = time.monotonic()
        result = op.result(handle, 10.0)
        assert result is not None and not result.success, result
        assert 'silent' in result.message and 'rig_driver' in result.message, result.message
        print(f'link cut: the goal ended {time.monotonic() - cut:.2f} s later: {result.message}')
        time.sleep(3.0)                                                       # the rig PC is on its own
        sh('ip', 'netns', 'exec', rig, 'ip', 'link', 'set', 'vrig', 'up')       # plugged in again (its routes too)
        sh('ip', 'netns', 'exec', rig, 'ip', 'route', 'replace', '224.0.0.0/4', 'dev', 'vrig')
        assert op.wait_status(lambda s: s.state in (RigStatus.STATE_FAULT, RigStatus.STATE_IDLE)
                              and abs(s.position) < 1e-6, 30.0), \
            'the rig PC did not bring the rig to rest:\n' + procs.log('rig_driver')[-3000:]
        print(f'rig PC after the cut: {op.status.state_name}, {list(op.status.fault_messages)}')
        assert any('stream lost' in m for m in op.status.fault_messages), list(op.status.fault_messages)
        op.trigger('rig_driver/reset')
        assert op.wait_ready(30.0), list(op.status.fault_messages)
        after = op.run(PROGRAM, timeout=60.0)
        assert after is not None and after.success, after and after.message
    finally:
        op.close()
        procs.stop_all()
