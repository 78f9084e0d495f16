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

"""DDS discovery stays on this machine unless a user asks: the test set-up, the benchmarks that touch ROS
and the `rubber-rig` entry point default ROS_AUTOMATIC_DISCOVERY_RANGE to LOCALHOST before rclpy loads,
and keep a value the user set."""
import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
VAR = 'ROS_AUTOMATIC_DISCOVERY_RANGE'


def _run(code, **env):
    base = {k: v for k, v in os.environ.items() if k != VAR}
    out = subprocess.run([sys.executable, '-c', code], cwd=ROOT, env={**base, **env}, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


@pytest.mark.parametrize('env,expected', [({}, 'LOCALHOST'), ({VAR: ''}, 'LOCALHOST'), ({VAR: 'SUBNET'}, 'SUBNET')])
def test_conftest_sets_the_default_at_import(env, expected):
    code = f'import os, runpy; runpy.run_path("test/conftest.py"); print(os.environ["{VAR}"])'
    assert _run(code, **env) == expected


def _touches_ros(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(a.name.split('.')[0] in ('rclpy', 'subprocess') for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and node.module and (
                node.module.split('.')[0] == 'rclpy' or node.module.startswith(('rubber_rig.nodes', 'rubber_rig.cli'))):
            return True
    return False


def _sets_default_first(tree):
    """The module's first statements set the default before any import other than os/__future__."""
    for stmt in tree.body:
        if isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Constant):     # docstring
            continue
        if isinstance(stmt, ast.ImportFrom) and stmt.module == '__future__':
            continue
        if isinstance(stmt, ast.Import) and [a.name for a in stmt.names] == ['os']:
            continue
        text = ast.unparse(stmt)
        return VAR in text and 'LOCALHOST' in text
    return False


BENCHMARKS = sorted((ROOT / 'benchmarks').glob('*.py'))


@pytest.mark.parametrize('script', BENCHMARKS, ids=[p.name for p in BENCHMARKS])
def test_benchmarks_that_touch_ros_default_to_localhost_first(script):
    tree = ast.parse(script.read_text())
    if not _touches_ros(tree) and not _sets_default_first(tree):
        pytest.skip(f'{script.name} uses no ROS and starts no process')
    assert _sets_default_first(tree), f'{script.name}: set the {VAR} default before the other imports'


@pytest.mark.parametrize('env,expected', [({}, 'LOCALHOST'), ({VAR: 'SUBNET'}, 'SUBNET')])
def test_a_benchmark_header_sets_the_default_and_keeps_a_choice(env, expected):
    script = ROOT / 'benchmarks' / 'bench_suite.py'
    tree = ast.parse(script.read_text())
    header = [s for s in tree.body[:4] if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
    code = ast.unparse(ast.Module(body=[s for s in header if not isinstance(s, ast.ImportFrom)], type_ignores=[]))
    assert _run(code + f'\nprint(os.environ["{VAR}"])', **env) == expected
