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

"""Static checks of the launch files (launch/launch_ros are not on PyPI, so they cannot run here).

For every launch file: it compiles; every Node action names an executable that setup.py installs; every
parameter file it passes exists, is installed by setup.py, and only sets parameters the node declares (the
nodes are instantiated with real rclpy to list what they declare); every inline parameter override is
declared too; every LaunchConfiguration is declared with DeclareLaunchArgument; rig_driver, a lifecycle node,
is started as a launch_ros LifecycleNode.
"""
import ast
import importlib
import inspect
from pathlib import Path

import pytest
import rclpy
import yaml
from rclpy.node import Node

from support.package import console_scripts_specs

ROOT = Path(__file__).resolve().parents[1]
LAUNCH_FILES = sorted((ROOT / 'launch').glob('*.launch.py'))


def console_scripts() -> dict:
    specs = console_scripts_specs()
    return {s.split('=')[0].strip(): s.split('=')[1].strip() for s in specs}


def _kw(call: ast.Call, name: str):
    for k in call.keywords:
        if k.arg == name:
            return k.value
    return None


def _call_name(call: ast.Call) -> str:
    f = call.func
    return f.id if isinstance(f, ast.Name) else getattr(f, 'attr', '')


class LaunchFile:
    """What a launch file references, read from its syntax tree."""

    def __init__(self, path: Path):
        self.path = path
        self.source = path.read_text()
        self.tree = ast.parse(self.source, filename=str(path))
        self.assignments = {t.id: n.value for n in ast.walk(self.tree) if isinstance(n, ast.Assign)
                            for t in n.targets if isinstance(t, ast.Name)}
        calls = [n for n in ast.walk(self.tree) if isinstance(n, ast.Call)]
        self.nodes = [c for c in calls if _call_name(c) in ('Node', 'LifecycleNode')]
        self.lifecycle_nodes = {_kw(c, 'executable').value for c in calls if _call_name(c) == 'LifecycleNode'}
        self.declared_args = {c.args[0].value for c in calls if _call_name(c) == 'DeclareLaunchArgument'}
        self.used_args = {c.args[0].value for c in calls if _call_name(c) == 'LaunchConfiguration'}

    def resolve(self, expr):
        return self.assignments.get(expr.id, expr) if isinstance(expr, ast.Name) else expr

    def config_file(self, expr) -> str:
        """os.path.join(<share>, 'config', 'x.yaml') -> 'config/x.yaml'."""
        expr = self.resolve(expr)
        assert isinstance(expr, ast.Call) and _call_name(expr) == 'join', ast.dump(expr)
        parts = [a.value for a in expr.args if isinstance(a, ast.Constant)]
        return '/'.join(parts)


def flatten(d: dict, prefix: str = '') -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(flatten(v, f'{prefix}{k}.'))
        else:
            out[f'{prefix}{k}'] = v
    return out


@pytest.fixture(scope='module')
def declared(tmp_path_factory):
    """executable -> {parameter name: descriptor}, from instantiating each node class with real rclpy."""
    out = {}
    context = rclpy.context.Context()
    rclpy.init(context=context)
    safe = {  # keep the instantiation side-effect free: no bus opened, no file written
        'rig_driver': {'autostart': False},
        'recorder': {'autostart': False, 'output_dir': str(tmp_path_factory.mktemp('rec'))},
    }
    try:
        used = {_kw(c, 'executable').value for f in LAUNCH_FILES for c in LaunchFile(f).nodes}
        for exe, target in console_scripts().items():
            module_name = target.split(':')[0]
            if exe not in used:
                continue
            module = importlib.import_module(module_name)
            classes = [c for _, c in inspect.getmembers(module, inspect.isclass)
                       if issubclass(c, Node) and c.__module__ == module.__name__]
            assert len(classes) == 1, f'{module_name}: expected one node class, found {classes}'
            overrides = [rclpy.parameter.Parameter(k, value=v) for k, v in safe.get(exe, {}).items()]
            node = classes[0](context=context, parameter_overrides=overrides)
            try:
                names = node.list_parameters([], 0).names
                out[exe] = {n: node.describe_parameter(n) for n in names}
            finally:
                node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    return out


def test_there_are_launch_files_for_sim_and_can():
    assert {p.name for p in LAUNCH_FILES} == {'rig_sim.launch.py', 'rig_can.launch.py'}


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_file_compiles_and_defines_generate_launch_description(path):
    lf = LaunchFile(path)
    compile(lf.source, str(path), 'exec')
    funcs = [n.name for n in lf.tree.body if isinstance(n, ast.FunctionDef)]
    assert 'generate_launch_description' in funcs
    assert lf.used_args <= lf.declared_args, f'undeclared launch arguments: {lf.used_args - lf.declared_args}'


@pytest.mark.ros
@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_file_references_exist_and_are_declared(path, declared):
    lf = LaunchFile(path)
    scripts = console_scripts()
    setup_text = (ROOT / 'setup.py').read_text()
    assert "glob('config/*.yaml')" in setup_text, 'config files must be installed to share/rubber_rig/config'
    executables = set()
    for call in lf.nodes:
        assert _kw(call, 'package').value == 'rubber_rig'
        exe = _kw(call, 'executable').value
        executables.add(exe)
        assert exe in scripts, f'{path.name}: executable {exe!r} is not a console_script of setup.py'
        name = _kw(call, 'name').value
        params = _kw(call, 'parameters')
        assert isinstance(params, ast.List) and params.elts, f'{exe}: no parameters'
        for item in params.elts:
            item = lf.resolve(item)
            if isinstance(item, ast.Dict):   # inline overrides
                keys = [k.value for k in item.keys]
                missing = set(keys) - set(declared[exe])
                assert not missing, f'{path.name}: {exe} does not declare {missing}'
                continue
            rel = lf.config_file(item)
            cfg = ROOT / rel
            assert cfg.is_file(), f'{path.name}: parameter file {rel} does not exist'
            data = yaml.safe_load(cfg.read_text())
            section = data.get(f'/**/{name}') or data.get(name)
            assert section and 'ros__parameters' in section, f'{rel}: no section for node {name}'
            missing = set(flatten(section['ros__parameters'])) - set(declared[exe])
            assert not missing, f'{rel}: node {name} ({exe}) does not declare {sorted(missing)}'
    assert executables == {'rig_driver', 'excitation', 'element_model', 'recorder'}
    # the driver is a lifecycle node: launch_ros must know it (ros2 lifecycle, lifecycle events in launch)
    assert lf.lifecycle_nodes == {'rig_driver'}, f'{path.name}: rig_driver must be a LifecycleNode action'


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_rig_driver_is_a_lifecycle_node_brought_up_by_autostart_or_by_the_operator(path):
    """rig_driver is a managed node: launch_ros.actions.LifecycleNode (as the ros2 lifecycle demos start one, with
    the name and namespace it requires). The launch files emit no ChangeState events: the driver's parameter file
    says whether it configures and activates itself (autostart) or waits for the operator's `ros2 lifecycle set`,
    and the launch file's docstring says which."""
    lf = LaunchFile(path)
    imported = {a.name for n in ast.walk(lf.tree) if isinstance(n, ast.ImportFrom) and n.module == 'launch_ros.actions'
                for a in n.names}
    assert 'LifecycleNode' in imported, f'{path.name}: LifecycleNode must come from launch_ros.actions'
    [driver] = [c for c in lf.nodes if _call_name(c) == 'LifecycleNode']
    assert _kw(driver, 'executable').value == 'rig_driver'
    assert _kw(driver, 'name') is not None and _kw(driver, 'namespace') is not None, \
        f'{path.name}: a LifecycleNode needs name= and namespace='
    assert not {'ChangeState', 'EmitEvent', 'RegisterEventHandler'} & {_call_name(c) for c in ast.walk(lf.tree)
                                                                       if isinstance(c, ast.Call)}
    files = [lf.config_file(p) for p in _kw(driver, 'parameters').elts if not isinstance(lf.resolve(p), ast.Dict)]
    overrides = [k.value for p in _kw(driver, 'parameters').elts if isinstance(lf.resolve(p), ast.Dict)
                 for k in lf.resolve(p).keys]
    assert 'autostart' not in overrides
    [cfg] = files
    autostart = yaml.safe_load((ROOT / cfg).read_text())['/**/rig_driver']['ros__parameters']['autostart']
    doc = ast.get_docstring(lf.tree)
    if autostart is True:
        assert 'autostart: true' in doc, f'{path.name}: the docstring should say the driver activates itself'
    else:
        assert autostart is False and 'ros2 lifecycle set' in doc, \
            f'{path.name}: {cfg} must set autostart, and without it the docstring must say how to bring it up'


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_only_the_nodes_that_restart_safely_are_respawned(path):
    """element_model and the recorder come back on their own after a crash; rig_driver (the safety authority)
    and the excitation (which would start its `program` again) do not."""
    lf = LaunchFile(path)
    respawned = {}
    for c in lf.nodes:
        kw = _kw(c, 'respawn')
        respawned[_kw(c, 'executable').value] = kw is not None and lf.resolve(kw).value is True
    assert respawned == {'rig_driver': False, 'excitation': False, 'element_model': True, 'recorder': True}


@pytest.mark.ros
def test_every_node_parameter_has_a_description(declared):
    for exe, params in declared.items():
        for name, d in params.items():
            if name == 'use_sim_time':
                continue
            assert d.description.strip(), f'{exe}: parameter {name} has no description'
            if d.type in (2, 3):   # INTEGER, DOUBLE: ranges on every number except free offsets
                assert d.integer_range or d.floating_point_range, \
                    f'{exe}: numeric parameter {name} has no range'


@pytest.mark.ros
def test_config_values_have_the_declared_types(declared):
    """A config value of the wrong type would fail at node start; catch it here (ints allowed for doubles)."""
    type_ok = {1: (bool,), 2: (int,), 3: (int, float), 4: (str,)}
    for cfg in sorted((ROOT / 'config').glob('rig_*.yaml')):
        data = yaml.safe_load(cfg.read_text())
        for key, section in data.items():
            exe = key.split('/')[-1]
            for name, value in flatten(section['ros__parameters']).items():
                d = declared[exe][name]
                if d.type in type_ok:
                    assert isinstance(value, type_ok[d.type]) and not (d.type != 1 and isinstance(value, bool)), \
                        f'{cfg.name}: {exe}.{name} = {value!r} has the wrong type'
