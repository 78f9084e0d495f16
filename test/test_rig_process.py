"""The simulated rig as a separate process across a process-crossing bus: python-can's udp_multicast on
loopback (this machine's kernel has no vcan module; a vcan/socketcan channel works the same through
RigConfig.backend = "socketcan")."""
import random

import numpy as np
import pytest

from rubber_rig.excitation import Program
from rubber_rig.rig import open_rig, run_program

pytest.importorskip('msgpack', reason='python-can udp_multicast needs msgpack')


def test_run_program_against_a_separate_process_rig_over_udp_multicast():
    port = random.randint(43200, 48000)     # a private port: other rigs on this host stay apart
    cfg = {'backend': 'udp_multicast', 'channel': '239.74.163.2', 'bus_options': {'port': port},
           'spawn_sim': True, 'paced': False, 'sim': {'seed': 3}}
    prog = Program.from_yaml_text('name: xproc\nblocks:\n  - {waveform: sine, frequency: 10 Hz, amplitude: 0.5 mm, '
                                  'cycles: 5}\n')
    with open_rig(cfg) as rig:
        assert rig.process is not None and rig.process.poll() is None
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
