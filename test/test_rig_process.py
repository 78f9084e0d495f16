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
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rubber_rig.excitation import Program
from rubber_rig.rig import open_rig
from rubber_rig.session import run_program

from support.netns import NETNS_MARK, ROOT, multicast_routes, netns_id, unshare_command

pytest.importorskip('msgpack', reason='python-can udp_multicast needs msgpack')


def test_run_program_against_a_separate_process_rig_over_udp_multicast():
    host_netns = os.environ.get(NETNS_MARK)
    if host_netns is None:          # on the host: re-run this test inside a private network namespace
        prefix, reason = unshare_command()
        if prefix is None:
            pytest.skip(reason)
        env = dict(os.environ, **{NETNS_MARK: netns_id()})
        test_id = f'{Path(__file__).resolve()}::test_run_program_against_a_separate_process_rig_over_udp_multicast'
        # the re-run's own limit (pytest-timeout) ends it with a traceback, shown below, before this test's
        # subprocess timeout, and both before the 300 s per-test limit of setup.cfg ends this test
        proc = subprocess.run([*prefix, sys.executable, '-m', 'pytest', test_id, '-x', '-q', '-p', 'no:cacheprovider',
                               '--timeout=240'], cwd=ROOT, env=env, capture_output=True, text=True, timeout=270)
        assert proc.returncode == 0 and '1 passed' in proc.stdout, proc.stdout[-4000:] + proc.stderr[-2000:]
        return
    # inside the namespace: prove the isolation before sending anything
    assert netns_id() != host_netns
    assert [name for _, name in socket.if_nameindex()] == ['lo']
    assert ('224.0.0.0', '240.0.0.0', 'lo') in multicast_routes()
    assert all(iface == 'lo' for _, _, iface in multicast_routes())
    port = random.randint(43200, 48000)     # a private port: other rigs on this host stay apart
    cfg = {'backend': 'udp_multicast', 'channel': '239.74.163.2', 'bus_options': {'port': port},
           'spawn_sim': True, 'paced': False, 'sim': {'seed': 3}}
    prog = Program.from_yaml_text('name: xproc\nblocks:\n  - {waveform: sine, frequency: 10 Hz, amplitude: 0.5 mm, '
                                  'cycles: 5}\n')
    with open_rig(cfg) as rig:
        assert rig.process is not None and rig.process.poll() is None
        assert netns_id(rig.process.pid) == netns_id()       # the rig process shares the private namespace
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
