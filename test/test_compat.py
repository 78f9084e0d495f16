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
PRIVATE = re.compile(r'mcap_ros2\._dynamic|_for_each_msgdef|_rclpy_pybind11|\._parameter_overrides\b|'
                     r'\._parameters\b|\._state_machine\b')


def test_private_third_party_names_appear_only_in_the_compat_modules():
    offenders = []
    for folder in ('rubber_rig', 'test', 'benchmarks'):
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
    assert rclpy_compat.version_matches(rclpy_compat.installed_version())
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
    assert issubclass(rclpy_compat.RCLError, Exception)
