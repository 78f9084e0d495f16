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

"""The running nodes use the DDS configuration the README states: with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
(the suite's default) every node process runs Fast DDS with the shipped config/fastdds_localhost.xml - UDP on
127.0.0.1 only, no shared-memory transport - and still finds the others; a range or profile file the user
chose is kept. Checked on the processes themselves (their threads and sockets), not on the variables alone.
"""
import os
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from rubber_rig import dds
from rubber_rig.testing.operator import Operator
from rubber_rig.testing.processes import NODES, SuiteProcesses

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config' / 'rig_sim.yaml'
PROFILE = ROOT / 'config' / dds.LOCALHOST_PROFILE
SUBNET_PROFILE = ROOT / 'config' / dds.SUBNET_PROFILE
NS = '/ddsprofile'
PROGRAM = """name: dds
blocks:
  - {name: a, waveform: sine, frequency: 5 Hz, amplitude: 0.1 mm, cycles: 3}
"""
pytestmark = [pytest.mark.ros, pytest.mark.slow]
DOMAIN = 230 + os.getpid() % 2      # a domain of our own (the profile reaches 64 participant ports up to 231)


def threads(pid: int) -> set[str]:
    names = set()
    for t in os.listdir(f'/proc/{pid}/task'):
        try:
            names.add(Path(f'/proc/{pid}/task/{t}/comm').read_text().strip())
        except OSError:
            pass
    return names


def udp_addresses(pid: int) -> set[str]:
    out = subprocess.run(['ss', '-uanpH'], capture_output=True, text=True, check=True).stdout
    return {line.split()[3].rsplit(':', 1)[0] for line in out.splitlines() if f'pid={pid},' in line}


def udp_buffers(pid: int) -> list[tuple[int, int]]:
    """(SO_RCVBUF, SO_SNDBUF) of each UDP socket of `pid` as the kernel reports them (ss -m: rb, tb; twice the
    value set, capped by net.core.rmem_max / wmem_max)."""
    out = subprocess.run(['ss', '-uanpmH'], capture_output=True, text=True, check=True).stdout
    lines, sizes = out.splitlines(), []
    for line, nxt in zip(lines, lines[1:] + [''], strict=True):
        if f'pid={pid},' in line:
            mem = (line if 'skmem:' in line else nxt).split('skmem:(')[1]
            fields = dict((f[:2], f[2:]) for f in mem.rstrip(')').split(','))
            sizes.append((int(fields['rb']), int(fields['tb'])))
    return sizes


@pytest.fixture(scope='module')
def suite(tmp_path_factory):
    base = tmp_path_factory.mktemp('dds')
    env = {k: v for k, v in os.environ.items() if k not in (dds.PROFILES_VARIABLE, dds.PINNED_MARK)}
    env[dds.RANGE_VARIABLE] = 'LOCALHOST'
    procs = SuiteProcesses(CONFIG, NS, DOMAIN, base / 'logs', {'recorder': {'output_dir': str(base / 'rec')}})
    procs.env = dict(env, ROS_DOMAIN_ID=str(DOMAIN), PYTHONUNBUFFERED='1')
    procs.start_all()
    op = Operator(NS, DOMAIN)
    try:
        assert op.wait_ready(60.0), procs.log('rig_driver')[-2000:]
        assert all(procs.wait_started(node) for node in NODES)
        yield procs, op
    finally:
        op.close()
        procs.stop_all()


def test_every_node_runs_udp_on_loopback_without_shared_memory(suite):
    procs, op = suite
    for node in NODES:
        pid = procs.procs[node].pid
        names = threads(pid)
        assert any(n.startswith('dds.udp') for n in names), (node, names)
        assert not any(n.startswith('dds.shm') for n in names), f'{node} runs shared memory: {sorted(names)}'
        assert udp_addresses(pid) == {'127.0.0.1'}, (node, udp_addresses(pid))
        # the profile's 4 MiB buffers, as far as the kernel allows: every receiving socket has the receive buffer,
        # the one sending socket the send buffer
        rmem_max = int(Path('/proc/sys/net/core/rmem_max').read_text())
        wmem_max = int(Path('/proc/sys/net/core/wmem_max').read_text())
        buffers = udp_buffers(pid)
        assert all(rb >= min(4194304, rmem_max) or tb >= min(4194304, wmem_max) for rb, tb in buffers), \
            (node, buffers)
        assert sum(rb >= min(4194304, rmem_max) for rb, _ in buffers) >= 2, (node, buffers)
        log = procs.log(node)
        assert f'DDS: localhost only: Fast DDS profile {PROFILE}' in log, log[-1500:]
    # and they found each other: a program runs through all four, recorded, with the model predicting it
    result = op.run(PROGRAM, timeout=30.0)
    assert result is not None and result.success, result
    # the goal's result can come before this process has taken the last batches (a busy computer: 286 of them seen)
    assert op.wait_for(lambda: op.last_sequence > 500 and op.predicted_until > 500
                       and op.recorder is not None and op.recorder.messages_written > 10, 10.0), \
        (op.last_sequence, op.predicted_until, op.recorder)


def test_the_profile_is_what_the_readme_states():
    root = ET.parse(PROFILE).getroot()
    ns = {'d': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    transports = root.findall('.//d:transport_descriptor', ns)
    assert [t.find('d:type', ns).text for t in transports] == ['UDPv4']
    assert [a.text for a in root.findall('.//d:interfaceWhiteList/d:address', ns)] == ['127.0.0.1']
    assert root.find('.//d:useBuiltinTransports', ns).text == 'false'
    assert root.find('.//d:maxInitialPeersRange', ns).text == '64'
    # a datagram the kernel dropped is repaired at the writer's next heartbeat: 50 ms, not Fast DDS's 3 s
    assert root.find('.//d:data_writer/d:times/d:heartbeatPeriod/d:nanosec', ns).text == '50000000'
    assert root.find('.//d:receiveBufferSize', ns).text == '4194304'
    readme = (ROOT / 'README.md').read_text()
    assert 'config/fastdds_localhost.xml' in readme and 'no shared memory' in readme


@pytest.mark.parametrize('env,range_,profile', [
    ({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}, 'SYSTEM_DEFAULT', PROFILE),
    ({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}, 'SUBNET', SUBNET_PROFILE),
    ({}, None, SUBNET_PROFILE),                        # a node started by hand: the ROS default (SUBNET)
    ({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_STATIC_PEERS': '10.0.0.2'}, 'LOCALHOST', None),
    ({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'FASTRTPS_DEFAULT_PROFILES_FILE': '/x.xml'}, 'LOCALHOST',
     '/x.xml'),
])
def test_configure_dds_keeps_what_the_user_chose(env, range_, profile):
    env = dict(env)
    first = dds.configure_dds(env)
    assert env.get(dds.RANGE_VARIABLE) == range_
    assert env.get(dds.PROFILES_VARIABLE) == (str(profile) if profile else None)
    if profile is None or profile == SUBNET_PROFILE:
        assert env[dds.TRANSPORTS_VARIABLE] == 'UDPv4'
    child = dict(env)
    assert dds.configure_dds(child) == first and child == env      # a child process keeps the choice
    assert dds.configure_dds({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}).startswith('RMW rmw_cyclonedds_cpp')
