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

"""Node processes stop promptly and cleanly: the suite started the way ``ros2 launch``
starts it (rubber_rig.testing.processes), each node sent SIGINT (Ctrl-C, launch's shutdown) or SIGTERM and timed
until its process has ended. Each must end within EXIT_WITHIN seconds with exit status 0 and no traceback.

* The rig idle and no program running (the brief's case): measured here 0.2-0.4 s per node, most of it the
  interpreter's own teardown (the node's clean-up takes milliseconds).
* A controller gone silent during a program: rig_driver's close() waited the whole 5 s for a ramp that no status
  frame would ever report (5.3 s measured), now it does not wait for a silent controller.
* No "Failed to publish log message to rosout" on the way out: rclpy's signal handler shut the context down before
  the node's close() logged ("rig closed", the recorder's "closed"); rubber_rig.nodes.spin now stops the executor
  itself and shuts the context down last.
* SIGINT twice at once (a terminal's Ctrl-C reaches ``ros2 launch`` and its nodes, and launch sends its own): the
  second one interrupted the clean-up with a KeyboardInterrupt traceback (or ended the process before it), exit
  status -2; now it is ignored while the clean-up runs.
"""
import contextlib
import os
import signal
import time
from pathlib import Path

import pytest

from msg_defs.msg import RigStatus
from rubber_rig.testing.operator import Operator
from rubber_rig.testing.processes import NODES, SuiteProcesses

# System tier: each test judges an exit on the wall clock ("within 2 s"), which a busy computer stretches (2.15 s
# seen for the recorder with a load of 6); the shutdown ramp's logic is the driver's core (test_rig_shutdown, on
# simulated time) and make test's end-to-end tests stop their nodes with the same signals.
pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.system]

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'rig_sim.yaml'
NS = '/shutdown'
EXIT_WITHIN = 2.0   # [s] from the signal to the end of the process
ROSOUT_FAILURE = 'Failed to publish log message to rosout'   # rcl's line (stderr) for a log call after shutdown
LONG = """name: long
blocks:
  - {name: s5, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 200, taper_cycles: 1}
"""


def domain_id() -> int:
    """A DDS domain of this module's own, 150..160."""
    return 150 + os.getpid() % 11


def stop_timed(procs: SuiteProcesses, node: str, sig: int) -> tuple[float, int | None]:
    """Send `sig` to the node's process; (seconds until it ended, exit status; None if it outlived 10 s)."""
    proc = procs.procs[node]
    t0 = time.monotonic()
    proc.send_signal(sig)
    try:
        code = proc.wait(timeout=10.0)
    except Exception:   # noqa: BLE001 - reported by the caller's assertion; SuiteProcesses.stop kills it
        code = None
    return time.monotonic() - t0, code


def check_clean_exit(procs: SuiteProcesses, node: str, seconds: float, code: int | None) -> None:
    log = procs.log(node)
    assert code == 0, f'{node}: exit status {code}\n{log[-3000:]}'
    assert seconds < EXIT_WITHIN, f'{node}: {seconds:.2f} s to exit\n{log[-3000:]}'
    assert 'Traceback' not in log, log[-3000:]
    assert ROSOUT_FAILURE not in log, log[-3000:]


@contextlib.contextmanager
def started_suite(tmp_path):
    """The four nodes started and ready, with an operator; everything stopped afterwards."""
    procs = SuiteProcesses(CONFIG, NS, domain_id(), tmp_path / 'logs',
                           {'recorder': {'output_dir': str(tmp_path / 'recordings')}})
    op = None
    try:
        procs.start_all()
        op = Operator(NS, domain_id())
        assert op.wait_ready(60.0), 'suite did not come up:\n' + procs.log('rig_driver')[-2000:]
        for node in NODES:
            assert procs.wait_started(node, 30.0), f'{node} did not start:\n' + procs.log(node)[-2000:]
        yield procs, op
    finally:
        if op is not None:
            op.close()
        procs.stop_all()


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_every_node_exits_within_2_s_of_the_signal_with_the_rig_idle(tmp_path, sig):
    with started_suite(tmp_path) as (procs, op):
        assert op.status.state == RigStatus.STATE_IDLE and not op.status.stream_owner   # no program running
        times = {}
        for node in NODES:   # one after the other, the rest of the suite still up
            seconds, code = stop_timed(procs, node, sig)
            times[node] = seconds
            check_clean_exit(procs, node, seconds, code)
        print(f'{signal.Signals(sig).name}: ' + ', '.join(f'{n} {t:.2f} s' for n, t in times.items()))


def test_sigint_twice_at_once_still_cleans_up_every_node(tmp_path):
    with started_suite(tmp_path) as (procs, op):
        t0 = time.monotonic()
        for _ in range(2):          # the terminal's and launch's SIGINT, to every node at once
            for node in NODES:
                procs.procs[node].send_signal(signal.SIGINT)
        for node in NODES:
            try:
                code = procs.procs[node].wait(timeout=10.0)
            except Exception:   # noqa: BLE001 - reported below
                code = None
            check_clean_exit(procs, node, time.monotonic() - t0, code)
        assert 'rig closed' in procs.log('rig_driver')            # close() ran to its end
        assert 'closed 1 file(s)' in procs.log('recorder')


def test_rig_driver_exits_within_2_s_when_its_controller_went_silent(tmp_path):
    procs = SuiteProcesses(CONFIG, NS, domain_id(), tmp_path / 'logs', {
        'rig_driver': {'sim': {'faults': '[{type: silent_controller, start: 1.0}]'}},
        'excitation': {'amplitude_control': False}})
    op = None
    try:
        procs.start('rig_driver')
        procs.start('excitation')
        op = Operator(NS, domain_id())
        assert op.wait_ready(60.0), 'rig did not come up:\n' + procs.log('rig_driver')[-2000:]
        handle = op.send_goal(LONG)
        assert handle is not None and handle.accepted
        assert op.wait_status(lambda s: s.state == RigStatus.STATE_FAULT, 20.0), procs.log('rig_driver')[-2000:]
        assert 'silent' in ' '.join(op.status.fault_messages)
        seconds, code = stop_timed(procs, 'rig_driver', signal.SIGINT)
        print(f'rig_driver with a silent controller: {seconds:.2f} s')
        check_clean_exit(procs, 'rig_driver', seconds, code)
        assert 'controller silent (watchdog fault): not waiting' in procs.log('rig_driver')
    finally:
        if op is not None:
            op.close()
        procs.stop_all()
