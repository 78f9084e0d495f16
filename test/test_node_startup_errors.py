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

"""Node processes that are given bad parameters, started the way ``ros2 launch`` starts them
(rubber_rig.testing.processes) and judged by their exit status and their log: one line naming the parameter and
what is wrong, never a Python traceback.

* element_model with a parameter_set it cannot use (missing, binary, not YAML, YAML of the wrong layout) ends at
  start with one FATAL line and exit status 2; the same files set at run time (``ros2 param set``) are refused
  with the reason and the running model stays.
* rig_driver with a sample_rate its CAN bus cannot carry stays up and unconfigured: configure fails with one
  line naming sample_rate, the bus and its bitrates and the highest rate it carries; after ``ros2 param set``
  of a rate that fits, configure and activate work.
"""
import os
from pathlib import Path

import pytest
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters

from msg_defs.msg import ModelParameters, RigStatus
from rubber_rig.nodes import topics
from rubber_rig.nodes.spin import EXIT_BAD_PARAMETER
from rubber_rig.rig.config import RigConfig
from rubber_rig.testing.operator import Operator
from rubber_rig.testing.processes import SuiteProcesses

pytestmark = [pytest.mark.ros, pytest.mark.slow]

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'rig_sim.yaml'
NS = '/startup'
START = 30.0    # [s] a node process starts (imports, DDS) well within this on a loaded 2-core machine


def domain_id() -> int:
    """A DDS domain of this module's own, 150..160."""
    return 150 + os.getpid() % 11


@pytest.fixture
def procs(tmp_path):
    p = SuiteProcesses(CONFIG, NS, domain_id(), tmp_path / 'logs')
    yield p
    p.stop_all()


@pytest.fixture
def operator():
    op = Operator(NS, domain_id())
    yield op
    op.close()


def no_traceback(log: str) -> None:
    assert 'Traceback' not in log, log[-3000:]


def lines_with(log: str, text: str) -> list[str]:
    return [line for line in log.splitlines() if text in line]


# -- element_model: parameter_set ------------------------------------------------------------------------------
BAD_SETS = {   # file content (None: no file) -> the problem the error line names
    'missing': (None, 'no such file'),
    'binary': (b'\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe\x00', 'not a YAML text file'),
    'not_yaml': (b'sets: [unclosed\n  fit: {model: seed000\n', 'not valid YAML'),
    'wrong_layout': (b'- 1.2e7\n- 1.4e7\n', 'no "sets" mapping'),
}


def bad_set_file(tmp_path: Path, case: str) -> tuple[str, str]:
    content, problem = BAD_SETS[case]
    path = tmp_path / f'{case}.yaml'
    if content is not None:
        path.write_bytes(content)
    return str(path), problem


# one bad file proves the wiring (the node exits with one line naming it) in make test; the other kinds of bad
# file are the parser's (test_online_model_file, in-process) and each costs a node start (5-8 s): system tier
@pytest.mark.parametrize('case', [case if case == 'missing' else pytest.param(case, marks=pytest.mark.system)
                                  for case in BAD_SETS])
def test_element_model_with_a_bad_parameter_set_exits_with_one_line(procs, tmp_path, case):
    path, problem = bad_set_file(tmp_path, case)
    proc = procs.start('element_model', {'parameter_set': path})
    code = proc.wait(START)
    log = procs.log('element_model')
    no_traceback(log)
    assert code == EXIT_BAD_PARAMETER, (code, log[-3000:])
    errors = lines_with(log, "parameter 'parameter_set'")
    assert len(errors) == 1, log[-3000:]
    assert '[FATAL]' in errors[0] and path in errors[0] and problem in errors[0], errors[0]
    assert ']: ready' not in log


def set_parameter(op: Operator, node: str, name: str, value):
    """``ros2 param set <node> <name> <value>`` (a string or a double); the SetParametersResult."""
    if isinstance(value, str):
        msg = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
    else:
        msg = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(value))
    request = SetParameters.Request(parameters=[ParameterMsg(name=name, value=msg)])
    response = op.call(f'{node}/set_parameters', SetParameters, request, timeout=10.0)
    assert response is not None, f'{node}/set_parameters did not answer'
    return response.results[0]


def test_a_bad_parameter_set_at_run_time_is_refused_and_the_model_stays(procs, operator, tmp_path):
    models: list[ModelParameters] = []
    operator.node.create_subscription(ModelParameters, topics.MODEL_PARAMETERS, models.append, topics.LATCHED_QOS)
    procs.start('element_model', {'parameter_set': 'swing_arm_joint_20C'})
    assert procs.wait_started('element_model', START), procs.log('element_model')[-3000:]
    assert operator.wait_for(lambda: models, 10.0), 'no model_parameters from element_model'
    assert models[-1].parameter_set == 'swing_arm_joint_20C'
    for case in BAD_SETS:
        path, problem = bad_set_file(tmp_path, case)
        result = set_parameter(operator, 'element_model', 'parameter_set', path)
        assert not result.successful, case
        assert result.reason.startswith('parameter_set:') and path in result.reason and problem in result.reason, \
            result.reason
    # the parameter and the model are what they were; a good set is still taken
    got = operator.call('element_model/get_parameters', GetParameters,
                        GetParameters.Request(names=['parameter_set']), timeout=10.0)
    assert got is not None and got.values[0].string_value == 'swing_arm_joint_20C'
    assert models[-1].parameter_set == 'swing_arm_joint_20C' and procs.alive('element_model')
    assert set_parameter(operator, 'element_model', 'parameter_set', 'swing_arm_joint_0C').successful
    assert operator.wait_for(lambda: models[-1].parameter_set == 'swing_arm_joint_0C', 10.0)
    no_traceback(procs.log('element_model'))


# -- rig_driver: sample_rate beyond the bus ------------------------------------------------------------------
def lifecycle(op: Operator, transition: int) -> bool:
    r = op.call('rig_driver/change_state', ChangeState, ChangeState.Request(transition=Transition(id=transition)),
                timeout=10.0)
    assert r is not None, 'rig_driver/change_state did not answer'
    return r.success


def lifecycle_state(op: Operator) -> int:
    r = op.call('rig_driver/get_state', GetState, GetState.Request(), timeout=10.0)
    assert r is not None, 'rig_driver/get_state did not answer'
    return r.current_state.id


def test_rig_driver_with_a_sample_rate_the_bus_cannot_carry_stays_unconfigured(procs, operator):
    too_fast = 20000.0                     # the default bus (CAN FD 1/5 Mbit/s, packed frames) carries ~18 kHz
    bus = RigConfig(sample_rate=1000.0)
    most = bus.bus_load().rate_at(bus.max_bus_load)
    assert too_fast > most
    procs.start('rig_driver', {'sample_rate': too_fast})     # autostart: it configures itself at start
    assert procs.wait_started('rig_driver', START), procs.log('rig_driver')[-3000:]
    assert operator.wait_status(lambda s: s.state == RigStatus.STATE_UNCONFIGURED, 10.0)
    assert operator.status.sample_rate == too_fast
    assert lifecycle_state(operator) == State.PRIMARY_STATE_UNCONFIGURED and procs.alive('rig_driver')
    log = procs.log('rig_driver')
    errors = lines_with(log, 'configure failed')
    assert len(errors) == 1, log[-3000:]
    line = errors[0]
    assert '[ERROR]' in line and "parameter 'sample_rate'" in line and '20000 Hz' in line and 'stays unconfigured' \
        in line, line
    assert '1/5 Mbit/s CAN FD bus' in line and f'this bus carries at most {most:.0f} Hz' in line, line
    no_traceback(log)

    # configure again unchanged: refused the same way, still up
    assert not lifecycle(operator, Transition.TRANSITION_CONFIGURE)
    assert len(lines_with(procs.log('rig_driver'), 'configure failed')) == 2 and procs.alive('rig_driver')
    # a rate the bus carries (accepted while unconfigured), then configure and activate
    result = set_parameter(operator, 'rig_driver', 'sample_rate', 1000.0)
    assert result.successful, result.reason
    assert lifecycle(operator, Transition.TRANSITION_CONFIGURE)
    assert lifecycle_state(operator) == State.PRIMARY_STATE_INACTIVE
    assert lifecycle(operator, Transition.TRANSITION_ACTIVATE)
    assert operator.wait_status(lambda s: s.state == RigStatus.STATE_IDLE and s.sample_rate == 1000.0, 10.0), \
        operator.status
    no_traceback(procs.log('rig_driver'))
