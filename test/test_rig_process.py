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

"""The simulated rig as a separate process across a process-crossing bus: python-can's udp_multicast on
loopback (this machine's kernel has no vcan module; a vcan/socketcan channel works the same through
RigConfig.backend = "socketcan").

The multicast traffic must not leave the machine: the test re-runs itself (and so the rig process it
spawns) in a private network namespace that has only a loopback interface, with the multicast route on
lo. Creating one needs root, or unprivileged user namespaces; elsewhere the test is skipped, never run on
the host's network.
"""
import os
import random
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rubber_rig.excitation import Program
from rubber_rig.rig import open_rig, run_program

pytest.importorskip('msgpack', reason='python-can udp_multicast needs msgpack')

ROOT = Path(__file__).resolve().parents[1]
NETNS_MARK = 'RUBBER_RIG_TEST_PRIVATE_NETNS'     # set to the host's netns id in the re-run inside the namespace
NETNS_SETUP = 'ip link set lo up && ip route add 224.0.0.0/4 dev lo && exec "$@"'


def _netns_id(pid='self'):
    return os.readlink(f'/proc/{pid}/ns/net')


def _unshare_command():
    """`unshare` arguments for a fresh network namespace set up for multicast on lo, or a skip reason."""
    unshare, ip = shutil.which('unshare'), shutil.which('ip')
    if unshare is None or ip is None:
        return None, ('the udp_multicast test needs a private network namespace: '
                      f'{"unshare (util-linux)" if unshare is None else "ip (iproute2)"} is not installed')
    cmd = [unshare, '--net']
    if os.geteuid() != 0:                 # unprivileged: a user namespace grants the network capabilities
        cmd = [unshare, '--user', '--map-root-user', '--net']
    probe = subprocess.run([*cmd, 'sh', '-c', NETNS_SETUP, 'sh', 'true'], capture_output=True, text=True,
                           timeout=30)
    if probe.returncode != 0:
        who = 'as root' if os.geteuid() == 0 else 'without root (user namespaces)'
        return None, (f'cannot create a private network namespace {who} for the udp_multicast test '
                      f'(unshare/ip: {probe.stderr.strip() or probe.returncode}); not running it on the host network')
    return [*cmd, 'sh', '-c', NETNS_SETUP, 'sh'], None


def _multicast_routes():
    """IPv4 routes of this process's network namespace as (destination, mask, interface)."""
    routes = []
    for line in Path('/proc/self/net/route').read_text().splitlines()[1:]:
        iface, dest, _, _, _, _, _, mask = line.split()[:8]
        routes.append((socket.inet_ntoa(bytes.fromhex(dest)[::-1]), socket.inet_ntoa(bytes.fromhex(mask)[::-1]),
                       iface))
    return routes


def test_run_program_against_a_separate_process_rig_over_udp_multicast():
    host_netns = os.environ.get(NETNS_MARK)
    if host_netns is None:          # on the host: re-run this test inside a private network namespace
        prefix, reason = _unshare_command()
        if prefix is None:
            pytest.skip(reason)
        env = dict(os.environ, **{NETNS_MARK: _netns_id()})
        test_id = f'{Path(__file__).resolve()}::test_run_program_against_a_separate_process_rig_over_udp_multicast'
        # the re-run's own limit (pytest-timeout) ends it with a traceback, shown below, before this test's
        # subprocess timeout, and both before the 300 s per-test limit of setup.cfg ends this test
        proc = subprocess.run([*prefix, sys.executable, '-m', 'pytest', test_id, '-x', '-q', '-p', 'no:cacheprovider',
                               '--timeout=240'], cwd=ROOT, env=env, capture_output=True, text=True, timeout=270)
        assert proc.returncode == 0 and '1 passed' in proc.stdout, proc.stdout[-4000:] + proc.stderr[-2000:]
        return
    # inside the namespace: prove the isolation before sending anything
    assert _netns_id() != host_netns
    assert [name for _, name in socket.if_nameindex()] == ['lo']
    assert ('224.0.0.0', '240.0.0.0', 'lo') in _multicast_routes()
    assert all(iface == 'lo' for _, _, iface in _multicast_routes())
    port = random.randint(43200, 48000)     # a private port: other rigs on this host stay apart
    cfg = {'backend': 'udp_multicast', 'channel': '239.74.163.2', 'bus_options': {'port': port},
           'spawn_sim': True, 'paced': False, 'sim': {'seed': 3}}
    prog = Program.from_yaml_text('name: xproc\nblocks:\n  - {waveform: sine, frequency: 10 Hz, amplitude: 0.5 mm, '
                                  'cycles: 5}\n')
    with open_rig(cfg) as rig:
        assert rig.process is not None and rig.process.poll() is None
        assert _netns_id(rig.process.pid) == _netns_id()       # the rig process shares the private namespace
        r = run_program(prog, cfg, rig=rig)
    assert r.completed, r.message
    n = prog.n_samples(1000.0)
    assert r.final_status.frames_malformed == 0
    got = r.sequence < n
    assert np.count_nonzero(got) + r.final_status.frames_lost == n
    np.testing.assert_allclose(r.setpoint[got], prog.setpoints(1000.0)[r.sequence[got]], atol=0.6e-7)
    # same physics as in-process: an in-process run with the same seed gives the same samples
    local = run_program(prog, {'paced': False, 'sim': {'seed': 3}})
    same = np.isin(local.sequence, r.sequence)
    np.testing.assert_array_equal(local.displacement[same][:n], r.displacement[np.isin(r.sequence, local.sequence)][:n])
    assert r.blocks[0].achieved_amplitude == pytest.approx(local.blocks[0].achieved_amplitude, rel=1e-3)
