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

"""The layer rules of the package, written down as a test (an AST scan of every module, no imports).

* ROS (rclpy, the interface packages) is used only by the nodes/ wiring and the cli/ that starts nodes.
* The core subpackages import one another only along the edges in ALLOWED: what a newcomer reads in the
  layout of the README (safety and models at the bottom; excitation, rig, recording above them; session
  above excitation and rig; fitting above; nodes and cli on top). Nothing in rig/ imports excitation/.
* No function-local imports in the core, except optional heavy ones (matplotlib, only needed for reports).
"""
import ast
import importlib
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / 'rubber_rig'
ROS_MODULES = {'rclpy', 'msg_defs', 'rcl_interfaces', 'builtin_interfaces', 'std_msgs', 'std_srvs',
               'diagnostic_msgs', 'lifecycle_msgs', 'launch', 'launch_ros', 'ament_index_python'}
ROS_LAYERS = {'nodes', 'launching', 'cli', 'testing'}
# subpackage (or top-level module) -> the parts of rubber_rig it may import
ALLOWED = {
    'settings': set(),
    'units': set(),
    'versions': set(),
    'paths': set(),
    'cpu': set(),
    'dds': {'paths'},
    'security': set(),
    'analysis': set(),
    'safety': {'settings'},
    'models': {'analysis', 'units'},
    'excitation': {'models', 'safety', 'settings', 'units'},
    'recording': {'__init__', 'versions'},
    'rig': {'models', 'safety', 'settings'},
    'session': {'excitation', 'online', 'recording', 'rig', 'safety'},
    'online': {'analysis', 'excitation', 'models'},
    'fitting': {'analysis', 'excitation', 'models', 'recording', 'rig', 'session', 'units'},
    'nodes': {'analysis', 'cpu', 'dds', 'excitation', 'models', 'online', 'paths', 'recording', 'rig', 'safety',
              'security', 'session', 'settings', 'versions'},
    'launching': {'dds', 'nodes'},
    'cli': {'__init__', 'analysis', 'cpu', 'excitation', 'fitting', 'launching', 'models', 'nodes', 'online', 'paths',
            'recording', 'rig', 'safety', 'security', 'session', 'settings', 'units'},
    'testing': {'cli', 'cpu', 'dds', 'nodes'},
}
OPTIONAL_HEAVY = {'matplotlib'}


def _modules():
    for path in sorted(PACKAGE.rglob('*.py')):
        parts = path.relative_to(PACKAGE).parts
        layer = parts[0] if len(parts) > 1 else parts[0][:-3]
        yield path, layer, ast.parse(path.read_text(encoding='utf-8'), str(path))


def _imported(node, path):
    """Absolute names a node imports."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if node.level:
        package = ('rubber_rig',) + path.relative_to(PACKAGE).parts[:-1]
        base = package[:len(package) - node.level + 1]
        return ['.'.join(base + ((node.module,) if node.module else ()))]
    return [node.module]


MODULES = list(_modules())


def test_every_layer_is_known():
    assert {layer for _, layer, _ in MODULES} - {'__init__'} <= set(ALLOWED)


@pytest.mark.parametrize('path, layer, tree', MODULES, ids=[str(p.relative_to(PACKAGE)) for p, _, _ in MODULES])
def test_layer_rules(path, layer, tree):
    where = path.relative_to(PACKAGE.parent)
    for node in ast.walk(tree):
        if not isinstance(node, (ast.Import, ast.ImportFrom)):
            continue
        for name in _imported(node, path):
            top = name.split('.')[0]
            if top in ROS_MODULES:
                assert layer in ROS_LAYERS, f'{where}:{node.lineno} imports {name}: ROS belongs in nodes/ or cli/'
            if top == 'rubber_rig' and layer != '__init__':
                target = name.split('.')[1] if '.' in name else '__init__'
                assert target == layer or target in ALLOWED[layer], \
                    f'{where}:{node.lineno}: {layer} may not import rubber_rig.{target}'
    if layer in ROS_LAYERS:
        return
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for node in ast.walk(fn):
                if isinstance(node, (ast.Import, ast.ImportFrom)):
                    names = _imported(node, path)
                    assert all(n.split('.')[0] in OPTIONAL_HEAVY for n in names), \
                        f'{where}:{node.lineno}: function-local import of {", ".join(names)} (import at the top)'


def test_the_scan_catches_a_violation():
    """The rules bite: a core module importing rclpy, a function-local import, a forbidden edge."""
    with pytest.raises(AssertionError, match='ROS belongs'):
        test_layer_rules(PACKAGE / 'models' / 'bad.py', 'models', ast.parse('import rclpy\n'))
    with pytest.raises(AssertionError, match='function-local import of numpy'):
        test_layer_rules(PACKAGE / 'models' / 'bad.py', 'models', ast.parse('def f():\n    import numpy\n'))
    with pytest.raises(AssertionError, match='models may not import rubber_rig.rig'):
        test_layer_rules(PACKAGE / 'models' / 'bad.py', 'models', ast.parse('from rubber_rig.rig import x\n'))


def test_test_modules_share_helpers_through_support_only():
    """A test module imports helpers from test/support, never from another test module (whose import would also
    collect and run its tests' module-level set-up)."""
    test_dir = Path(__file__).resolve().parent
    test_modules = {p.stem for p in test_dir.glob('test_*.py')}
    offenders = []
    for path in sorted(test_dir.rglob('*.py')):
        tree = ast.parse(path.read_text(encoding='utf-8'), str(path))
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ''] if isinstance(node, ast.ImportFrom) else [])
            offenders += [f'{path.name}:{node.lineno} imports {n}' for n in names if n.split('.')[0] in test_modules]
    assert not offenders, '\n'.join(offenders)


def test_the_readme_shows_the_layer_table_this_test_enforces():
    readme = (PACKAGE.parent / 'README.md').read_text(encoding='utf-8')
    section = readme.split('### Layers', 1)[1].split('\n## ', 1)[0]
    shown = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        if len(cells) == 2 and cells[0] not in ('layer', '---'):
            deps = set() if cells[1] == '-' else {d.strip() for d in cells[1].split(',')}
            shown[cells[0]] = {'__init__' if d == 'rubber_rig (version)' else d for d in deps}
    assert shown == ALLOWED


# Size rules: no function over MAX_FUNCTION_LINES in the core (not nodes/, cli/, testing/), no module over
# MAX_MODULE_LINES anywhere in the package. Nothing exceeds them; a module that must (a data table) would be listed
# in OVERSIZE_MODULES with its size and the reason beside it, and nothing may grow past what is listed.
MAX_FUNCTION_LINES = 80
MAX_MODULE_LINES = 400
OVERSIZE_FUNCTIONS: dict = {}      # 'path.py:function': lines
OVERSIZE_MODULES: dict = {}        # 'path.py': lines  (why)


def _sizes():
    functions, modules = {}, {}
    for path, layer, tree in MODULES:
        rel = str(path.relative_to(PACKAGE))
        modules[rel] = len(path.read_text(encoding='utf-8').splitlines())
        if layer in ROS_LAYERS:
            continue
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                functions[f'{rel}:{node.name}'] = max(functions.get(f'{rel}:{node.name}', 0),
                                                      node.end_lineno - node.lineno + 1)
    return functions, modules


def test_functions_and_modules_stay_small():
    functions, modules = _sizes()
    problems = []
    for sizes, listed, limit, what in ((functions, OVERSIZE_FUNCTIONS, MAX_FUNCTION_LINES, 'function'),
                                       (modules, OVERSIZE_MODULES, MAX_MODULE_LINES, 'module')):
        for name, n in sorted(sizes.items()):
            if n > limit and n > listed.get(name, limit):
                problems.append(f'{what} {name}: {n} lines (limit {limit}'
                                + (f', listed at {listed[name]})' if name in listed else ')'))
        for name in sorted(listed):
            if sizes.get(name, 0) <= limit:
                problems.append(f'{what} {name} now meets the {limit}-line rule: remove it from the list')
    assert not problems, '\n'.join(problems)


def _imported_names(path: Path):
    """(module, name, line) of every `from rubber_rig... import name` in `path`, at any depth."""
    for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split('.')[0] == 'rubber_rig':
            for alias in node.names:
                yield node.module, alias.name, node.lineno


def test_benchmarks_and_scripts_import_names_that_exist():
    """The benchmarks import from the package inside functions too, where nothing but a run would notice a name
    that moved (bench_suite imported READY_STATES from the excitation node after it had moved)."""
    missing = []
    for folder in ('benchmarks', 'scripts'):
        for path in sorted((PACKAGE.parent / folder).glob('*.py')):
            for module, name, line in _imported_names(path):
                found = importlib.import_module(module)
                if not hasattr(found, name):
                    try:
                        importlib.import_module(f'{module}.{name}')
                    except ImportError:
                        missing.append(f'{path.name}:{line}: {name} is not in {module}')
    assert not missing, '\n'.join(missing)


# ---- no raw clock in nodes/ (issue 34) ------------------------------------------------------------------------
# Every time-dependent decision takes `now` from an injected clock in the ROS-free core; a node is an adapter.
# The raw clock calls still in nodes/ are counted here, one number for the whole layer, and it may only go down:
# a new call fails this test, a removed one asks for the number to be lowered. The test's message lists where
# they are. Target: 0.
RAW_CLOCKS = {('time', 'monotonic'), ('time', 'time'), ('time', 'perf_counter'), ('time', 'monotonic_ns'),
              ('time', 'time_ns'), ('time', 'perf_counter_ns')}
RAW_CLOCK_CALLS_IN_NODES = 0


def raw_clock_calls(tree: ast.Module) -> list:
    """Line numbers of calls of a raw clock (time.monotonic(), time.time(), ... also imported by name)."""
    by_name = {a.asname or a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module == 'time'
               for a in n.names if ('time', a.name) in RAW_CLOCKS}
    lines = []
    for n in ast.walk(tree):
        if not isinstance(n, ast.Call):
            continue
        f = n.func
        if (isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and (f.value.id, f.attr) in RAW_CLOCKS) \
                or (isinstance(f, ast.Name) and f.id in by_name):
            lines.append(n.lineno)
    return sorted(lines)


def test_nodes_call_no_more_raw_clocks_than_counted():
    found = {path.relative_to(PACKAGE).as_posix(): raw_clock_calls(tree) for path, layer, tree in MODULES
             if layer == 'nodes'}
    found = {path: lines for path, lines in found.items() if lines}
    total = sum(len(lines) for lines in found.values())
    where = '; '.join(f'{path}: {len(lines)} (lines {", ".join(map(str, lines))})' for path, lines in found.items())
    assert total <= RAW_CLOCK_CALLS_IN_NODES, f'{total} raw clock calls in nodes/ (take now from the core): {where}'
    assert total == RAW_CLOCK_CALLS_IN_NODES, f'only {total} raw clock calls left in nodes/: lower the count ({where})'


def test_the_clock_scan_catches_every_spelling():
    source = ('import time\nfrom time import monotonic as mono\nfrom time import sleep\n\n'
              'def f(clock=time.monotonic):\n    return time.time(), mono(), time.perf_counter(), clock(), sleep(0)\n')
    assert raw_clock_calls(ast.parse(source)) == [6, 6, 6]


# ---- no mixins sharing one state (issue 34) -------------------------------------------------------------------
# A class that inherits from more than one base, one of them a class of this package, is a mixin: its parts share
# one instance's attributes, so none of them can be read, tested or replaced alone (RigDriverNode was
# RigDriverParameters + LifecycleNode). Split by responsibility instead: a part is an object the class holds. Counted
# for the whole package, one number that may only go down, like the raw clocks. Target: 0.
MIXIN_CLASSES = 0


def project_classes() -> set:
    """Names of every class defined in rubber_rig."""
    return {n.name for _, _, tree in MODULES for n in ast.walk(tree) if isinstance(n, ast.ClassDef)}


def mixin_classes(tree: ast.Module, project: set) -> list:
    """(line, class, bases) of each class in ``tree`` with more than one base, at least one of them in ``project``."""
    found = []
    for n in ast.walk(tree):
        if isinstance(n, ast.ClassDef) and len(n.bases) > 1:
            bases = [ast.unparse(b) for b in n.bases]
            if any(b.split('.')[-1] in project for b in bases):
                found.append((n.lineno, n.name, bases))
    return found


def test_no_more_mixin_classes_than_counted():
    project = project_classes()
    found = [f'{path.relative_to(PACKAGE).as_posix()}:{line} {name}({", ".join(bases)})'
             for path, _, tree in MODULES for line, name, bases in mixin_classes(tree, project)]
    assert len(found) <= MIXIN_CLASSES, f'{len(found)} mixin classes (hold the parts instead): {"; ".join(found)}'
    assert len(found) == MIXIN_CLASSES, f'only {len(found)} mixin classes left: lower the count ({"; ".join(found)})'


def test_the_mixin_scan_tells_a_mixin_from_a_plain_subclass():
    source = ('class Part:\n    pass\n\nclass Other:\n    pass\n\nclass Mixed(Part, Other):\n    pass\n\n'
              'class Plain(Part):\n    pass\n\nclass Foreign(dict, Exception):\n    pass\n\n'
              'class Node(mod.Part, rclpy.Node):\n    pass\n')
    found = mixin_classes(ast.parse(source), {'Part', 'Other'})
    assert [(name, bases) for _, name, bases in found] == [('Mixed', ['Part', 'Other']),
                                                           ('Node', ['mod.Part', 'rclpy.Node'])]
