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

"""benchmarks/run_all.py: one command writes every benchmark's figures to docs/benchmarks/, with how they were run."""
import importlib.util
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location('run_all', ROOT / 'benchmarks' / 'run_all.py')
run_all = sys.modules['run_all'] = importlib.util.module_from_spec(_spec)   # dataclasses look it up
_spec.loader.exec_module(run_all)


def test_every_listed_benchmark_is_a_script_and_every_script_is_listed():
    scripts = {p.name for p in (ROOT / 'benchmarks').glob('bench_*.py')}
    listed = {b.script for b in run_all.BENCHMARKS}
    assert scripts <= listed                                          # every bench_*.py has its run
    assert all((ROOT / 'benchmarks' / name).is_file() for name in listed)   # (busy_load.py wraps one of them)
    assert len({b.name for b in run_all.BENCHMARKS}) == len(run_all.BENCHMARKS)


def test_a_run_writes_its_page_and_json_with_the_benchmarks_own_output(tmp_path):
    bench = next(b for b in run_all.BENCHMARKS if b.name == 'seed004_pad')
    rec = run_all.run(bench, tmp_path)
    assert rec['returncode'] == 0
    page = (tmp_path / 'seed004_pad.md').read_text(encoding='utf-8')
    assert '`.venv/bin/python benchmarks/bench_seed004_pad.py`' in page
    # the benchmark's table is there unedited: 12 points of Table 2, the first K_op 14.278 kN/mm
    rows = [line for line in page.splitlines() if line.startswith('| 2 | 0.3 | -0.9 |')]
    assert len(rows) == 1 and '| 14.278 |' in rows[0]
    saved = json.loads((tmp_path / 'seed004_pad.json').read_text(encoding='utf-8'))
    assert saved['returncode'] == 0 and saved['commit'] and saved['output'] == rec['output']
    index = run_all.write_index(tmp_path).read_text(encoding='utf-8')
    assert '[seed004_pad](seed004_pad.md)' in index and '| checks | ' in index and 'not run yet' in index


def test_a_failing_benchmark_still_gets_a_page_that_says_so(tmp_path):
    broken = run_all.Benchmark('broken', 'bench_checks.py', ('--rate', 'fast'), 'a bad argument', 0.1)
    rec = run_all.run(broken, tmp_path)
    assert rec['returncode'] == 2
    page = (tmp_path / 'broken.md').read_text(encoding='utf-8')
    assert 'FAILED (exit status 2)' in page and "invalid float value: 'fast'" in page


def test_an_unknown_benchmark_name_is_refused_with_the_list(capsys):
    with pytest.raises(SystemExit):
        run_all.main(['--only', 'modles'])
    err = capsys.readouterr().err
    assert "unknown benchmark 'modles'" in err and 'models' in err
