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
"""Every test that starts ROS 2 (an rclpy context, a node, the node suite in-process or as processes) carries
the ``ros`` marker, so ``pytest -m 'not ros'`` runs exactly the tests that need no DDS.

Read from the syntax tree of each test module: a test starts ROS when its body, a helper or fixture of its
module that it uses, or a fixture it takes as an argument does one of the things in STARTERS.
"""
import ast
from pathlib import Path

import pytest

TEST_DIR = Path(__file__).resolve().parent
# calls that start ROS in this process or in node processes the test launches
STARTER_NAMES = {'ros_context', 'start_suite', 'InProcessLauncher', 'SuiteProcesses', 'Operator'}
STARTER_ATTRIBUTES = {('rclpy', 'init'), ('rclpy', 'Context'), ('rclpy', 'create_node')}


def _is_fixture(fn: ast.FunctionDef) -> bool:
    for d in fn.decorator_list:
        d = d.func if isinstance(d, ast.Call) else d
        if (isinstance(d, ast.Attribute) and d.attr == 'fixture') or (isinstance(d, ast.Name) and d.id == 'fixture'):
            return True
    return False


def _has_ros_mark(expr: ast.AST) -> bool:
    """``pytest.mark.ros`` anywhere in a decorator or in the value of ``pytestmark``."""
    return any(isinstance(n, ast.Attribute) and n.attr == 'ros' and isinstance(n.value, ast.Attribute)
               and n.value.attr == 'mark' for n in ast.walk(expr))


def _starts_ros_itself(fn: ast.FunctionDef) -> bool:
    for n in ast.walk(fn):
        if isinstance(n, ast.Name) and n.id in STARTER_NAMES:
            return True
        if (isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)
                and (n.value.id, n.attr) in STARTER_ATTRIBUTES):
            return True
        if isinstance(n, ast.Call):
            f = n.func
            if isinstance(f, ast.Name) and f.id.endswith('Node'):                 # a node class instantiated
                return True
            if (isinstance(f, ast.Name) and f.id == 'main' and n.args and isinstance(n.args[0], ast.List)
                    and n.args[0].elts and isinstance(n.args[0].elts[0], ast.Constant)
                    and n.args[0].elts[0].value == 'bench'):                       # rubber-rig bench: the suite
                return True
    return False


def unmarked_ros_tests(tree: ast.Module) -> list:
    """Names of the test functions of a module that start ROS without the ``ros`` marker."""
    module_marked = any(isinstance(n, ast.Assign) and any(isinstance(t, ast.Name) and t.id == 'pytestmark'
                                                          for t in n.targets) and _has_ros_mark(n.value)
                        for n in tree.body)
    functions = {n.name: n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
    fixtures = {name for name, fn in functions.items() if _is_fixture(fn)}
    ros = {name for name, fn in functions.items() if _starts_ros_itself(fn)}
    while True:   # a helper of the module it calls, or a fixture it takes as an argument, starts ROS
        more = set()
        for name, fn in functions.items():
            if name in ros:
                continue
            called = {n.func.id for n in ast.walk(fn) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
            args = {a.arg for a in fn.args.args + fn.args.kwonlyargs} if name in fixtures or name[:5] == 'test_' \
                else set()
            if called & (ros - fixtures) or args & ros & fixtures:
                more.add(name)
        if not more:
            break
        ros |= more
    return sorted(name for name in ros if name.startswith('test_') and not module_marked
                  and not any(_has_ros_mark(d) for d in functions[name].decorator_list))


@pytest.mark.parametrize('path', sorted(TEST_DIR.glob('test_*.py')), ids=lambda p: p.name)
def test_tests_that_start_ros_carry_the_ros_marker(path):
    unmarked = unmarked_ros_tests(ast.parse(path.read_text(encoding='utf-8'), str(path)))
    assert not unmarked, f'{path.name}: start ROS without @pytest.mark.ros: {", ".join(unmarked)}'


def test_the_marker_check_catches_an_unmarked_test():
    source = '''
import pytest, rclpy

@pytest.fixture
def context():
    rclpy.init()

def helper():
    return RecorderNode()

def test_by_fixture(context):
    pass

def test_by_helper():
    helper()

def test_by_bench(tmp_path):
    main(['bench', '--fast'])

@pytest.mark.ros
def test_marked(context):
    pass

def test_without_ros():
    pass
'''
    assert unmarked_ros_tests(ast.parse(source)) == ['test_by_bench', 'test_by_fixture', 'test_by_helper']
    assert unmarked_ros_tests(ast.parse('import pytest\npytestmark = [pytest.mark.ros]\n' + source)) == []


def _marks_system(expr: ast.AST, aliases: set) -> bool:
    """``pytest.mark.system`` (or a module name bound to it) anywhere in a decorator or ``pytestmark``."""
    return any((isinstance(n, ast.Attribute) and n.attr == 'system' and isinstance(n.value, ast.Attribute)
                and n.value.attr == 'mark') or (isinstance(n, ast.Name) and n.id in aliases) for n in ast.walk(expr))


def tier_counts(tree: ast.Module) -> tuple[int, int]:
    """(test functions of make test, of make test-system) in a module, by the ``system`` marker."""
    aliases = {t.id for n in tree.body if isinstance(n, ast.Assign) and _marks_system(n.value, set())
               for t in n.targets if isinstance(t, ast.Name) and t.id != 'pytestmark'}
    module_system = any(isinstance(n, ast.Assign) and any(isinstance(t, ast.Name) and t.id == 'pytestmark'
                                                          for t in n.targets) and _marks_system(n.value, aliases)
                        for n in tree.body)
    tests = [n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
             and n.name.startswith('test_')]
    system = sum(1 for t in tests if module_system or any(_marks_system(d, aliases) for d in t.decorator_list))
    return len(tests) - system, system


def test_both_tiers_have_tests_so_neither_make_target_runs_none():
    """make test (-m "not system") and make test-system (-m system) each select tests: pytest's exit status 5
    (no tests collected) must never end either."""
    counts = [tier_counts(ast.parse(p.read_text(encoding='utf-8'), str(p))) for p in TEST_DIR.glob('test_*.py')]
    assert sum(c[0] for c in counts) > 100 and sum(c[1] for c in counts) > 0, counts
    sample = ast.parse('import pytest\nsystem = pytest.mark.system\n\n@system\ndef test_a():\n    pass\n\n'
                       '@pytest.mark.system\ndef test_b():\n    pass\n\ndef test_c():\n    pass\n')
    assert tier_counts(sample) == (1, 2)
