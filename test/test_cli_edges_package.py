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

"""package.xml as rosdep reads it: every key resolves in ros/rosdistro, every third-party import is declared.

CI has no network, so the keys are checked against test/data/rosdep_keys.txt: the relevant keys of
ros/rosdistro's rosdep/python.yaml and of jazzy/distribution.yaml, extracted at the commit named in the file.
Packages without a rosdep key cannot be declared (rosdep install would stop at an unknown key); they are
listed in package.xml's "pip-only dependencies" comment and pinned in requirements.txt.
"""
import ast
import pathlib
import re
import sys
import xml.etree.ElementTree as ET

ROOT = pathlib.Path(__file__).resolve().parents[1]
KEYS_FILE = ROOT / 'test' / 'data' / 'rosdep_keys.txt'

# top-level import name -> dependency that provides it (a rosdep key / ROS package, or a pip name)
IMPORT_PROVIDER = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'yaml': 'python3-yaml', 'can': 'python3-can',
    'cantools': 'python3-cantools-pip', 'matplotlib': 'python3-matplotlib',
    'mcap_ros2': 'mcap-ros2-support', 'mcap': 'mcap', 'foxglove': 'foxglove-sdk',
    'rclpy': 'rclpy', 'std_msgs': 'std_msgs', 'std_srvs': 'std_srvs', 'diagnostic_msgs': 'diagnostic_msgs',
    'builtin_interfaces': 'builtin_interfaces', 'rcl_interfaces': 'rcl_interfaces',
    'lifecycle_msgs': 'lifecycle_msgs', 'action_msgs': 'action_msgs', 'msg_defs': 'msg_defs',
    'ament_index_python': 'ament_index_python', 'launch': 'launch', 'launch_ros': 'launch_ros',
    # tests and benchmarks
    'pytest': 'python3-pytest', '_pytest': 'python3-pytest', 'rosbags': 'python3-rosbags-pip',
    'catkin_pkg': 'python3-catkin-pkg',
    'differint': 'differint', 'pytest_timeout': 'python3-pytest-timeout', 'rosgraph_msgs': 'rosgraph_msgs',
    'ament_copyright': 'ament_copyright', 'ament_flake8': 'ament_flake8', 'ament_pep257': 'ament_pep257',
}
LOCAL_TEST_PACKAGES = {'support'}    # test/support: the tests' shared helpers
WORKSPACE_PACKAGES = {'msg_defs'}     # built from this repository (msg_defs/package.xml)


def _vendored():
    known, absent, commit = set(), set(), None
    for line in KEYS_FILE.read_text().splitlines():
        if not line.strip() or line.startswith('#'):
            continue
        source, key = line.split()
        if source == 'rosdistro-commit':
            commit = key
        elif source == 'absent':
            absent.add(key)
        else:
            known.add(key)
    return known, absent, commit


def _package():
    root = ET.parse(ROOT / 'package.xml').getroot()
    deps = {tag: {e.text.strip() for e in root.findall(tag)}
            for tag in ('depend', 'build_depend', 'exec_depend', 'test_depend')}
    pip_only = set()
    for comment in re.findall(r'<!--(.*?)-->', (ROOT / 'package.xml').read_text(), re.S):
        if 'pip-only dependencies' in comment:
            pip_only |= set(re.findall(r'^\s*(?:test only:\s*)?([A-Za-z0-9_.-]+)\s+\(', comment, re.M))
    return deps, pip_only


def _requirements():
    names = set()
    for line in (ROOT / 'requirements.txt').read_text().splitlines():
        m = re.match(r'\s*([A-Za-z0-9_.-]+)', line.split('#')[0])
        if m:
            names.add(m.group(1).lower())
    return names


def _third_party_imports(*folders):
    # a test module, or a benchmark script importing its sibling (run from benchmarks/, it is on sys.path)
    local = {p.stem for d in ('test', 'benchmarks') for p in (ROOT / d).glob('*.py')} | {'rubber_rig'} \
        | LOCAL_TEST_PACKAGES
    found = {}
    for folder in folders:
        for f in sorted((ROOT / folder).rglob('*.py')):
            for node in ast.walk(ast.parse(f.read_text(), str(f))):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    top = name.split('.')[0]
                    if top not in sys.stdlib_module_names and top not in local:
                        found.setdefault(top, f.relative_to(ROOT).as_posix())
    return found


def test_vendored_key_list_names_its_rosdistro_commit():
    known, absent, commit = _vendored()
    assert commit and re.fullmatch(r'[0-9a-f]{40}', commit)
    assert known and not (known & absent)


def test_every_declared_key_is_a_rosdistro_key_or_a_workspace_package():
    known, absent, _ = _vendored()
    deps, _ = _package()
    for tag, keys in deps.items():
        for key in keys:
            assert key not in absent, f'<{tag}>{key}</{tag}> is not a rosdep key (see {KEYS_FILE.name})'
            assert key in known or key in WORKSPACE_PACKAGES, \
                f'<{tag}>{key}</{tag}> is not in the vendored rosdistro keys ({KEYS_FILE.name})'
    assert (ROOT / 'msg_defs' / 'package.xml').is_file()
    for wrong in ('python3-cantools', 'python3-mcap-ros2-support-pip'):   # the keys rosdep rejected
        assert all(wrong not in keys for keys in deps.values())


def test_pip_only_dependencies_have_no_key_and_are_pinned():
    known, absent, _ = _vendored()
    _, pip_only = _package()
    assert {'zstandard', 'lz4', 'foxglove-sdk', 'mcap', 'differint'} <= pip_only
    requirements = _requirements()
    for name in pip_only:
        assert name.lower() in requirements, f'{name} is documented as a pip dependency but not in requirements.txt'
        assert name not in known and f'python3-{name}' not in known and f'python3-{name}-pip' not in known, \
            f'{name} has a rosdep key: declare it in package.xml instead'
        assert f'python3-{name}' in absent or name in absent, f'{name}: record the failed key look-up'


def _check_provided(imports, declared, pip_only):
    missing = []
    for top, where in sorted(imports.items()):
        provider = IMPORT_PROVIDER.get(top)
        if provider is None:
            missing.append(f'{top} (imported in {where}) has no entry in IMPORT_PROVIDER')
        elif provider not in declared and provider not in pip_only:
            missing.append(f'{top} (imported in {where}) needs {provider} in package.xml')
    assert not missing, '\n'.join(missing)


def test_every_third_party_import_of_the_package_is_a_runtime_dependency():
    deps, pip_only = _package()
    runtime = deps['depend'] | deps['exec_depend']
    imports = _third_party_imports('rubber_rig', 'launch')
    assert 'rcl_interfaces' in imports and 'rcl_interfaces' in runtime
    _check_provided(imports, runtime, pip_only)


def test_every_third_party_import_of_tests_and_benchmarks_is_declared():
    deps, pip_only = _package()
    _check_provided(_third_party_imports('test', 'benchmarks'), set().union(*deps.values()), pip_only)
