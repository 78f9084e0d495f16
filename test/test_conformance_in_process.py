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

"""The conformance matrix of the simulator on simulated time (rig/conformance/in_process.py): the simulated
controller and the run share one clock on a simulated CAN bus (bitrate, arbitration, frame times), so every
requirement, the timing ones included, is judged on a deterministic trace of the controller. The correct
simulator passes all of them; each deliberate defect (conformance.defects.DEFECTS) fails exactly the requirements
it names; the offline mode reads the run's own CAN log to the same verdicts.

What this cannot show is real timing: the simulator in a process of its own, over a real python-can bus, on a host
that is busy - test_conformance (the wiring in make test, the whole matrix on the wall clock in a private network
namespace in the system tier).
"""
import pytest

from rubber_rig.rig.conformance.active import scenarios_judging
from rubber_rig.rig.conformance.defects import DEFECTS
from rubber_rig.rig.conformance.in_process import run_against_simulator
from rubber_rig.rig.conformance.log_segments import check_log
from rubber_rig.rig.conformance.requirements import REQUIREMENTS
from rubber_rig.rig.conformance.trace import read_log

CTRL = {r.id for r in REQUIREMENTS if r.id.startswith('CTRL')}
OFFLINE_CTRL = {r.id for r in REQUIREMENTS if r.offline and r.id.startswith('CTRL')}


def _verdicts(results) -> dict:
    return {r.id: r.status for r in results.ordered() if r.id.startswith('CTRL')}


def _why(results) -> list:
    return [(r.id, r.status, r.measured, r.detail) for r in results.ordered() if r.status != 'pass']


def test_the_correct_simulator_passes_every_requirement_and_offline_agrees_on_its_log(tmp_path):
    run, results = run_against_simulator()
    verdicts = _verdicts(results)
    assert not run.deviation and set(verdicts) == CTRL, _why(results)
    assert set(verdicts.values()) == {'pass'}, _why(results)       # timing included: on simulated time none is late
    measured = {r.id: r.measured for r in results.ordered()}
    assert 'ratio 1' in measured['CTRL-MEAS-1'], measured['CTRL-MEAS-1']
    # the offline mode on the run's own log: the same verdict on every requirement a log can show
    log = tmp_path / 'run.blf'
    run.trace_to_log(log)
    offline = check_log(read_log(log, 1000.0))
    assert {r.id: r.status for r in offline.ordered() if r.id in OFFLINE_CTRL} == \
        {rid: verdicts[rid] for rid in OFFLINE_CTRL}


@pytest.mark.parametrize('defect', sorted(DEFECTS))
def test_each_broken_simulator_fails_exactly_its_requirements(defect):
    """A short run of the scenarios that judge the defect's requirements: those fail, every other they judge
    passes.
    """
    expected = set(DEFECTS[defect][0])
    run, results = run_against_simulator((defect,), only=scenarios_judging(expected))
    failed = {rid for rid, status in _verdicts(results).items() if status == 'fail'}
    assert failed == expected, _why(results)


@pytest.mark.slow
@pytest.mark.system
@pytest.mark.parametrize('defect', sorted(DEFECTS))
def test_each_broken_simulator_fails_exactly_its_requirements_in_a_whole_run(defect):
    run, results = run_against_simulator((defect,))
    failed = {rid for rid, status in _verdicts(results).items() if status == 'fail'}
    assert failed == set(DEFECTS[defect][0]), _why(results)
    assert not run.deviation
