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

"""`rubber-rig conformance` against the simulated controller in a process of its own, over udp_multicast in a
private network namespace (real timing, nothing leaves the machine): the correct simulator passes every
requirement, each deliberately broken one fails exactly the requirements its defect breaks, and the offline
mode on the run's own log and on a log written by the driver agrees (docs/protocol.md).
"""
import os
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import can
import pytest
import yaml

from rubber_rig.cli.main import main
from rubber_rig.excitation import Program
from rubber_rig.rig import open_rig
from rubber_rig.rig.can.protocol import Protocol
from rubber_rig.rig.can.stream import StreamRefused
from rubber_rig.rig.config import RigConfig
from rubber_rig.rig.conformance.active import ConformanceRun
from rubber_rig.rig.conformance.defects import DEFECTS
from rubber_rig.rig.conformance.link import Envelope
from rubber_rig.rig.conformance.report import Results, to_junit
from rubber_rig.rig.conformance.requirements import REQUIREMENTS
from rubber_rig.rig.conformance.trace import read_log
from rubber_rig.rig.sim.controller import SimController
from rubber_rig.session import run_program

from support.netns import in_private_netns, rerun_in_private_netns

pytest.importorskip('msgpack', reason='python-can udp_multicast needs msgpack')

HERE = Path(__file__).resolve()
CTRL = {r.id for r in REQUIREMENTS if r.id.startswith('CTRL')}
OFFLINE_CTRL = {r.id for r in REQUIREMENTS if r.offline and r.id.startswith('CTRL')}
inside = pytest.mark.skipif(not os.environ.get('RUBBER_RIG_TEST_PRIVATE_NETNS'),
                            reason='runs inside the private network namespace of test_conformance_in_private_netns')


def _junit(path) -> dict:
    """requirement id -> 'pass' | 'fail' | 'not tested' | 'host late' from a JUnit report ('host late': not
    tested because this host was late, the report says by how much).
    """
    out = {}
    for case in ET.parse(path).getroot().iter('testcase'):
        skipped = case.find('skipped')
        out[case.get('name')] = ('fail' if case.find('failure') is not None else
                                 'host late' if skipped is not None and 'this host was late' in
                                 skipped.get('message', '') else
                                 'not tested' if skipped is not None else 'pass')
    return out


def _conformance(tmp_path, *args, timeout=120):
    junit = tmp_path / 'report.xml'
    proc = subprocess.run([sys.executable, '-m', 'rubber_rig.cli.main', 'conformance', *args, '--junit', str(junit)],
                          capture_output=True, text=True, timeout=timeout)
    return proc, (_junit(junit) if junit.exists() else {})


# the simulated rig gets the declared reference spring and ambient: measured values are judged (CTRL-MEAS-1..3)
MEASURED = ('--reference-spring', '10kN/mm±1%', '--ambient', '20degC±5K')

# requirements judged on the wall-clock timing of this host's processes: a shared CI host that stalls the
# simulator's process for tens of ms can fail them; such a run is repeated once (a controller that really
# breaks one fails it by a wide margin every time: 80 ms heartbeats, 0-8 ms jitter)
TIMING = {'CTRL-HB-1', 'CTRL-ST-1', 'CTRL-TEMP-1', 'CTRL-ID-2', 'CTRL-FB-2', 'CTRL-ST-3', 'CTRL-ST-4',
          # frames this host failed to read in time, or a host watchdog that ran late, where its own lateness
          # measurement missed it (host_timing): judged on the second run
          'CTRL-HB-2', 'CTRL-ST-2', 'CTRL-SEQ-1', 'CTRL-FB-1', 'CTRL-WD-1', 'CTRL-STREAM-4'}
# a run on a loaded host is incomplete, never failed, for this host's delays: the timing requirements it could
# not judge say 'not judged: this host was late by X ms' (exit status 4)
INCOMPLETE = 4


def _conformance_expecting(tmp_path, failing: set, *args):
    """Run conformance; once more if the failures differ from `failing` in timing requirements only."""
    proc, verdicts = _conformance(tmp_path, *args)
    failed = {k for k, v in verdicts.items() if v == 'fail'}
    if failed != failing and verdicts and (failed ^ failing) <= TIMING:
        proc, verdicts = _conformance(tmp_path, *args)
    return proc, verdicts


# system tier: the conformance matrix, and CTRL-FB-2 (arrival jitter), CTRL-WD-1 (ramp within 0.5 s of the last
# heartbeat) and the other TIMING requirements are judged on the wall-clock arrival of frames from a process of
# its own - what they measure is real timing, which a busy computer changes (4.77 ms jitter > 2 ms seen with a
# moderate extra load). The wiring is make test's: the test after this one. One namespace run per inner test:
# the whole matrix (a correct simulator, 20 defects, 20-40 s each) is more than one run's time limit.
INNER = (['test_correct_simulator_passes_and_offline_agrees', 'test_offline_on_a_log_written_by_the_driver']
         + [f'test_each_broken_simulator_fails_exactly_its_requirements[{d}]' for d in sorted(DEFECTS)])


@pytest.mark.slow
@pytest.mark.system
@pytest.mark.timeout(300)
@pytest.mark.parametrize('inner', INNER)
def test_conformance_in_private_netns(inner):
    """Host side: one test of the matrix below in a private network namespace (skipped where none can be made)."""
    if in_private_netns():
        pytest.skip('already inside the namespace')
    rc, out = rerun_in_private_netns(f'{HERE}::{inner}', timeout=280)
    if rc is None:
        pytest.skip(out)
    assert rc == 0 and '1 passed' in out and 'failed' not in out, out


@pytest.mark.slow
@pytest.mark.timeout(340)
def test_the_simulator_in_a_process_of_its_own_passes_conformance_over_a_real_bus():
    """End-to-end tier (make test): `rubber-rig conformance --sim` against the simulator in a process of its own
    over python-can's udp_multicast, in a private network namespace: every requirement not judged on this
    host's timing or on the simulator keeping up in real time passes (the wiring of bus, codec, driver and
    simulator across processes), or, on a host so loaded that it was late where a scenario judged, is not judged
    for that (host_excuse) - never failed. Those are the system tier's (test_conformance_in_private_netns).
    """
    if in_private_netns():
        pytest.skip('already inside the namespace')
    rc, out = rerun_in_private_netns(f'{HERE}::test_correct_simulator_passes_every_requirement_apart_from_timing',
                                     timeout=300)
    if rc is None:
        pytest.skip(out)
    assert rc == 0 and '1 passed' in out and 'failed' not in out, out


# besides TIMING, what a paced simulator process must keep up with in real time: the feedback rate, contiguous
# sequences, one applied setpoint per tick and the ramp within 0.5 s of host silence (CTRL-WD-1: 0.630 s seen
# under a moderate load, issue 34) (under a load average of 9 on two cores the simulator's process fell
# behind: 93 ms arrival jitter, a 19-sample gap, 1981 of 2000 setpoints applied). The wiring check leaves them to
# the system tier as well.
REAL_TIME = TIMING | {'CTRL-FB-1', 'CTRL-SEQ-1', 'CTRL-STREAM-4', 'CTRL-ST-2', 'CTRL-WD-1'}


@inside
def test_correct_simulator_passes_every_requirement_apart_from_timing(tmp_path):
    assert in_private_netns()
    # a run under a load average of 9-12 on two cores takes 60-150 s
    proc, online = _conformance(tmp_path, '--sim', '--power-up', '--envelope', '1mm', *MEASURED, timeout=240)
    assert set(online) == CTRL, proc.stdout[-3000:] + proc.stderr[-2000:]
    # beyond what a simulator must keep up with in real time, nothing fails: a scenario's verdict where this host
    # was late longer than the requirement allows is not judged ('host late'), the run incomplete
    assert {k for k, v in online.items() if v not in ('pass', 'host late')} <= REAL_TIME, proc.stdout[-3000:]
    wiring = {k for k, v in online.items() if v == 'pass'} - REAL_TIME
    # the wiring: frames, limits, ramps, faults, reset, power-up, identity, measured values - nearly all shown
    assert len(CTRL - REAL_TIME) >= 15 and len(wiring) >= len(CTRL - REAL_TIME) - 3, proc.stdout[-3000:]


@inside
def test_correct_simulator_passes_and_offline_agrees(tmp_path):
    assert in_private_netns()
    log = tmp_path / 'run.blf'
    proc, online = _conformance_expecting(tmp_path, set(), '--sim', '--power-up', '--envelope', '1mm', *MEASURED,
                                          '--can-log', str(log))
    assert set(online) == CTRL
    # every requirement passes, or is not judged because this host was late (then the run is incomplete)
    assert {k for k, v in online.items() if v not in ('pass', 'host late')} == set(), proc.stdout[-3000:]
    late = {k for k, v in online.items() if v == 'host late'}
    assert proc.returncode == (INCOMPLETE if late else 0), proc.stdout[-3000:] + proc.stderr[-2000:]
    # offline on the run's own log: the same verdicts on every requirement a log can show
    off = tmp_path / 'off'
    off.mkdir()
    proc, offline = _conformance(off, '--log', str(log), '--rate', '1kHz')
    # the conformance run breaks host rules on purpose (stale setpoints, streams past a refusal): only the
    # controller's verdicts are compared
    assert proc.returncode in (0, 1), proc.stdout[-3000:]
    # (the offline mode knows nothing of this host's timing: what online was not judged for it is left out)
    assert {k: offline[k] for k in OFFLINE_CTRL - late} == {k: online[k] for k in OFFLINE_CTRL - late}


@inside
@pytest.mark.parametrize('defect', sorted(DEFECTS))
def test_each_broken_simulator_fails_exactly_its_requirements(tmp_path, defect):
    assert in_private_netns()
    proc, online = _conformance_expecting(tmp_path, set(DEFECTS[defect][0]), '--sim', '--power-up', '--envelope',
                                          '1mm', *MEASURED, '--defect', defect)
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-2000:]
    failed = {k for k, v in online.items() if v == 'fail'}
    assert failed == set(DEFECTS[defect][0]), proc.stdout[-3000:]


@inside
def test_offline_on_a_log_written_by_the_driver(tmp_path):
    """The driver's own CAN log of a program on the separate-process simulator: every requirement a log shows
    passes, the host's duties included.
    """
    assert in_private_netns()
    for attempt in range(2):          # once more only if this host's timing failed a timing requirement
        log = tmp_path / f'driver{attempt}.log'
        cfg = {'backend': 'udp_multicast', 'channel': '239.74.163.9', 'bus_options': {'port': 44111 + attempt},
               'spawn_sim': True, 'paced': True, 'can_log': str(log)}
        prog = Program.from_yaml_text('name: xproc\nblocks:\n  - {waveform: sine, frequency: 2 Hz, amplitude: '
                                      '0.5 mm, cycles: 4}\n')
        with open_rig(cfg) as rig:
            r = run_program(prog, cfg, rig=rig)
        assert r.completed, r.message
        proc, offline = _conformance(tmp_path, '--log', str(log), '--rate', '1000Hz')
        failed = {k for k, v in offline.items() if v == 'fail'}
        if not (failed and failed <= TIMING):
            break
    assert proc.returncode == 0, proc.stdout[-3000:]
    for rid in ('HOST-HB-1', 'HOST-LIM-1', 'HOST-STREAM-1', 'CTRL-FRAME-1', 'CTRL-HB-1', 'CTRL-ST-1', 'CTRL-SEQ-1',
                'CTRL-FB-1', 'CTRL-FB-2', 'CTRL-ST-3'):
        assert offline[rid] == 'pass', (rid, proc.stdout[-3000:])


# ---- no bus needed ------------------------------------------------------------------------------------------

def test_an_online_run_needs_a_stated_envelope(capsys):
    with pytest.raises(SystemExit) as exc:
        main(['conformance', '--interface', 'virtual', '--channel', 'x'])
    assert exc.value.code == 2
    assert 'state the displacement envelope' in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(['conformance', '--sim', '--envelope', '1mm', '--envelope-lower', '0.2mm'])
    assert exc.value.code == 2 and 'must contain the rest position' in capsys.readouterr().err


def test_an_unconfirmed_run_sends_nothing(monkeypatch, capsys):
    """Without --yes the operator must type yes; anything else sends no frame."""
    listener = can.Bus(interface='virtual', channel='conformance_confirm', receive_own_messages=False)
    monkeypatch.setattr('sys.stdin', __import__('io').StringIO('no\n'))
    assert main(['conformance', '--interface', 'virtual', '--channel', 'conformance_confirm',
                 '--envelope', '1mm']) == 2
    assert 'not confirmed' in capsys.readouterr().err
    assert listener.recv(0.2) is None
    listener.shutdown()


# A heartbeat-only log: its controller owes status (10 ms) and temperature (100 ms) frames it never sent, so those
# requirements fail on any such log (the controller's fault, issue 36); the damage tests below check that the
# log's own damage adds no failure to them.
ABSENT_FRAMES_FAIL = {'CTRL-ST-1', 'CTRL-ST-2', 'CTRL-TEMP-1'}


def _failed(out: str) -> set:
    """The requirement ids a conformance report marks **FAIL**."""
    return {line.split('|')[1].strip() for line in out.splitlines() if '| **FAIL** |' in line}


def _heartbeat_log(path, n=40):
    """n controller heartbeats 50 ms apart, written by python-can; returns the file's lines."""
    proto = Protocol()
    with can.Logger(str(path)) as log:
        for k in range(n):
            msg = proto.encode('ControllerHeartbeat', {'HB_Counter': k + 1, 'HB_State': 1})
            msg.timestamp, msg.channel = 1000.0 + 0.05 * k, 'can0'
            log.on_message_received(msg)
    return path.read_text().splitlines()


def test_offline_reads_past_a_damaged_line(tmp_path, capsys):
    """A garbage line costs that line: the heartbeats before and after it are read and judged (each stretch on its
    own), the skipped line is named in the log's verdict, and no controller requirement fails for it."""
    path = tmp_path / 'a.log'
    lines = _heartbeat_log(path)
    path.write_text('\n'.join(lines[:20] + ['garbage line ###'] + lines[20:]) + '\n')
    code = main(['conformance', '--log', str(path)])
    out = capsys.readouterr().out
    # the damaged line is skipped and named; the heartbeats on both sides of it are read and judged (40 at 50 ms)
    assert '40 frames' in out and 'line 21: not a candump -L frame line' in out
    assert 'log verdict: DAMAGED LOG: 1 unreadable line skipped' in out
    assert 'median 50.0 ms' in out and '| CTRL-HB-2 |' in out
    # a controller heard for 0.95 s on each side must have sent status (10 ms) and temperature (100 ms): their
    # absence fails (the controller's fault, not the log's); the identity (1 s) is not owed in so short a log
    assert code == 1 and _failed(out) == ABSENT_FRAMES_FAIL, out
    assert '0 ControllerStatus frames in 0.950 s of controller traffic' in out   # judged stretch by stretch
    assert '| CTRL-ID-2 | ControllerIdentity every 1000 ms | not tested |' in out
    assert main(['conformance', '--log', str(tmp_path / 'x.txt')]) != 0
    assert 'unsupported suffix' in capsys.readouterr().err


def test_offline_names_time_going_backwards_as_the_logs_fault(tmp_path, capsys):
    """One line's time moved back 100 s (the issue's case): before, the heartbeat period failed the controller
    (99th percentile 62 s). Now the log's verdict names the frame and line, the frames stay in file order, and
    the controller's heartbeat is judged within the stretches on either side of it: it passes."""
    path = tmp_path / 'back.log'
    lines = _heartbeat_log(path)
    lines[20] = lines[20].replace('(1001.', '(901.')
    path.write_text('\n'.join(lines) + '\n')
    trace = read_log(path, 1000.0)
    assert [round(f.t, 3) for f in trace.frames[19:22]] == [1000.95, 901.0, 1001.05]   # file order, as stamped
    assert (trace.time_backwards, trace.time_jumps, trace.lines_skipped, trace.truncated) == (1, 0, 0, False)
    assert (trace.time_anomalies[0].frame, trace.time_anomalies[0].line) == (21, 21)
    assert trace.time_anomalies[0].step == pytest.approx(-99.95)
    code = main(['conformance', '--log', str(path)])
    out = capsys.readouterr().out
    assert code == 1 and _failed(out) == ABSENT_FRAMES_FAIL, out
    assert 'log verdict: DAMAGED LOG: time goes backwards 1 time' in out and 'frame 21 (line 21)' in out
    assert 'median 50.0 ms, 99th percentile 50.0 ms' in out


@pytest.mark.parametrize('keep', [4, 9])
def test_offline_reports_a_log_cut_mid_line_as_truncated_never_as_the_controller(tmp_path, capsys, keep):
    """The file ends inside its last frame line (a copy that stopped, a full disk). Cut `keep` characters into the
    data ('#' and 3 hex digits: unreadable; '#' and 8: four whole bytes, which candump -L would take for a
    shorter frame, a malformed heartbeat the controller would be blamed for): the log is truncated, its last line
    is counted as skipped, and no controller requirement fails for it (only the frames the log's controller never
    sent do: ABSENT_FRAMES_FAIL)."""
    path = tmp_path / 'cut.log'
    lines = _heartbeat_log(path)
    text = '\n'.join(lines)
    cut = text[:text.rindex('#') + keep]
    path.write_text(cut)
    trace = read_log(path, 1000.0)
    assert trace.truncated and trace.lines_skipped == 1 and len(trace.frames) == 39
    code = main(['conformance', '--log', str(path)])
    out = capsys.readouterr().out
    assert code == 1 and _failed(out) == ABSENT_FRAMES_FAIL, out
    why = 'not a candump -L frame line' if keep == 4 else 'the file ends inside this line'
    assert 'log verdict: DAMAGED LOG: TRUNCATED' in out and f'line 40: {why}' in out
    assert '0 of 39 controller frames malformed' in out


def test_a_sample_outside_the_envelope_aborts_the_run():
    """The load frame reads 0.9 mm off (a displacement offset): the first streamed samples are far from the
    command, so the run commands ABORT at once, judges nothing it did not see, and the controller ends at rest.
    """
    cfg = RigConfig.from_dict({'sim': {'displacement_offset': 0.9e-3}})
    sim_bus = can.Bus(interface='virtual', channel='conformance_envelope', receive_own_messages=False)
    bus = can.Bus(interface='virtual', channel='conformance_envelope', receive_own_messages=False)
    sim = SimController(sim_bus, 1000.0, cfg.sim, True)
    sim.start()
    try:
        run = ConformanceRun(bus, 1000.0, Envelope(-1e-3, 1e-3), log=lambda text: None)
        results = run.run()
        assert 'tracking error' in run.deviation or 'outside the envelope' in run.deviation
        assert results['CTRL-RAMP-1'].status == 'not tested' and 'run aborted' in results['CTRL-RAMP-1'].detail
        deadline = time.monotonic() + 5.0
        while sim.state != 'idle' and time.monotonic() < deadline:
            time.sleep(0.01)
        assert sim.state == 'idle' and abs(sim.u) < 1e-9           # ramped back to rest at 0
    finally:
        sim.stop()
        bus.shutdown()
        sim_bus.shutdown()


def test_junit_report_counts_each_verdict():
    res = Results()
    res.put('CTRL-HB-1', 'pass', 'median 50.0 ms')
    res.put('CTRL-WD-1', 'fail', 'still holding', 'must ramp')
    res.complete({'CTRL-PWR-1'}, 'needs a power cycle')
    root = ET.fromstring(to_junit(res, 'suite', 1.5).split('\n', 1)[1])
    suite = root.find('testsuite')
    assert (suite.get('tests'), suite.get('failures'), suite.get('skipped')) == ('3', '1', '1')
    assert root.find(".//testcase[@name='CTRL-WD-1']/failure").get('message') == 'must ramp'


def test_the_hardware_configuration_streams_only_to_an_identified_controller():
    """rig_can.launch.py reads config/rig_can.yaml: it must keep the identity check on."""
    params = yaml.safe_load((HERE.parents[1] / 'config' / 'rig_can.yaml').read_text())
    driver = params['/**/rig_driver']['ros__parameters']
    assert driver['require_identity'] is True and driver['controller_device'] == 0


def test_the_driver_refuses_a_controller_of_another_protocol_version():
    cfg = {'paced': False, 'sim': {'protocol_version': 3}}
    with open_rig(cfg) as rig:
        rig.wait_ready(2.0)
        why = rig.driver.why_not_ready()
        assert 'protocol version 3' in why and 'version 4' in why
        with pytest.raises(StreamRefused, match='refusing to stream'):
            rig.driver.open_stream('test')
    with open_rig({**cfg, 'require_identity': False}) as rig:     # explicitly waived: streams
        assert rig.wait_ready(2.0) and rig.driver.why_not_ready() == ''
