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

"""Private third-party APIs are used only behind the two compatibility modules, and those work as installed."""
import re
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COMPAT = {ROOT / 'rubber_rig' / 'recording' / 'mcap_compat.py', ROOT / 'rubber_rig' / 'nodes' / 'rclpy_compat.py'}
# mcap_ros2._dynamic (and its functions), rclpy's C module, rclpy.Node's and LifecycleNode's private attributes
PRIVATE = re.compile(r'\b_dynamic\b|serialize_dynamic|generate_dynamic|_for_each_msgdef|_rclpy_pybind11|'
                     r'\._parameter_overrides\b|\._parameters\b|\._state_machine\b')


def test_private_third_party_names_appear_only_in_the_compat_modules():
    offenders = []
    for folder in ('rubber_rig', 'test', 'benchmarks', 'launch'):
        for path in sorted((ROOT / folder).rglob('*.py')):
            if path in COMPAT or path == Path(__file__).resolve():
                continue
            for i, line in enumerate(path.read_text(encoding='utf-8').splitlines(), 1):
                if PRIVATE.search(line):
                    offenders.append(f'{path.relative_to(ROOT)}:{i}: {line.strip()}')
    assert not offenders, 'private third-party API outside the compat modules:\n' + '\n'.join(offenders)


def test_version_check_compares_major_minor():
    from rubber_rig.recording import mcap_compat
    assert mcap_compat.version_matches('0.6.3', '0.6.0') and not mcap_compat.version_matches('0.7.0', '0.6.0')
    with warnings.catch_warnings():
        warnings.simplefilter('error')         # the installed versions are the checked ones: no warning
        assert mcap_compat.version_matches(mcap_compat.installed_version())


def test_the_scan_catches_each_private_name():
    for line in ('from mcap_ros2._dynamic import generate_dynamic', 'from mcap_ros2 import _dynamic',
                 'from mcap_ros2._dynamic import _for_each_msgdef', 'from rclpy._rclpy_pybind11 import RCLError',
                 'node._parameter_overrides.get(name)', 'name in node._parameters',
                 'self._state_machine.current_state[1]'):
        assert PRIVATE.search(line), line
    assert not PRIVATE.search('ParameterDescriptor(dynamic_typing=True); self.parameters')


def test_check_version_warns_on_another_major_minor_and_does_not_fail():
    from rubber_rig.recording import mcap_compat
    with pytest.warns(RuntimeWarning, match='mcap-ros2-support 0.7.0 is installed'):
        assert mcap_compat.check_version('0.7.0') is False
    with pytest.warns(RuntimeWarning, match='version unknown'):
        assert mcap_compat.check_version('') is False
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert mcap_compat.check_version('0.6.9') is True
        assert mcap_compat.check_version() is True       # the installed version is the checked one


def test_mcap_compat_encodes_and_parses_a_definition():
    from rubber_rig.recording import mcap_compat
    from rubber_rig.recording.msgdefs import full_definition
    text = full_definition('msg_defs/msg/SetpointBatch')
    data = mcap_compat.encoder('msg_defs/msg/SetpointBatch', text)(
        {'first_sequence': 7, 'displacement': [1e-3, 2e-3], 'stream_id': 3})
    assert data[:2] == b'\x00\x01'                     # little-endian CDR
    seen = []
    mcap_compat.for_each_msgdef('msg_defs/msg/SetpointBatch', text, lambda full, short, spec: seen.append(short))
    assert 'msg_defs/SetpointBatch' in seen and 'std_msgs/Header' in seen


@pytest.mark.ros
def test_rclpy_compat_reads_overrides_and_lifecycle_state():
    import rclpy
    from rclpy.lifecycle import LifecycleNode
    from rclpy.parameter import Parameter

    from rubber_rig.nodes import rclpy_compat
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert rclpy_compat.check_version() is True
    with pytest.warns(RuntimeWarning, match='rclpy 8.0.0 is installed'):
        assert rclpy_compat.check_version('8.0.0') is False
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = LifecycleNode('compat_probe', context=context,
                             parameter_overrides=[Parameter('x', Parameter.Type.INTEGER, 3)])
        assert rclpy_compat.parameter_overrides(node)['x'].value == 3
        assert rclpy_compat.lifecycle_state(node) == 'unconfigured'
        node.trigger_configure()
        assert rclpy_compat.lifecycle_state(node) == 'inactive'
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert issubclass(rclpy_compat.RCLError, Exception) and rclpy_compat.RCLError.__name__ == 'RCLError'
