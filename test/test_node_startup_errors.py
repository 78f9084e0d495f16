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

"""Node processes that are given bad parameters (issue 24 point 9), started the way ``ros2 launch`` starts them
(rubber_rig.nodes.processes) and judged by their exit status and their log: one line naming the parameter and
what is wrong, never a Python traceback.

* element_model with a parameter_set it cannot use (missing, binary, not YAML, YAML of the wrong layout) ends at
  start with one FATAL line and exit status 2; the same files set at run time (``ros2 param set``) are refused
  with the reason and the running model stays.
"""
import os
from pathlib import Path

import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters

from msg_defs.msg import ModelParameters
from rubber_rig.nodes import topics
from rubber_rig.nodes.processes import Operator, SuiteProcesses
from rubber_rig.nodes.spin import EXIT_BAD_PARAMETER

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


@pytest.mark.parametrize('case', list(BAD_SETS))
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


def set_parameter(op: Operator, node: str, name: str, value: str):
    request = SetParameters.Request(parameters=[ParameterMsg(
        name=name, value=ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value))])
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
