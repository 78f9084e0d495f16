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

"""Programs from outside are read at a bounded cost: a YAML bomb, deep nesting and huge texts are refused
before anything is built, naming the limit; anchors and aliases of ordinary size still work.
"""
import os
import threading
import time

import pytest

from rubber_rig.excitation import yamltext
from rubber_rig.excitation.blocks import ProgramError
from rubber_rig.excitation.program import MAX_BLOCKS, Program, read_program
from rubber_rig.excitation.yamltext import MAX_BYTES, YAMLLimitError, load_bounded

BLOCK = '  - {waveform: sine, frequency: 1 Hz, amplitude: 1 mm, cycles: 1}\n'


def billion_laughs(levels: int = 9) -> str:
    lines = ['a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]']
    for i in range(1, levels):
        prev, cur = chr(96 + i), chr(97 + i)
        lines.append(f'{cur}: &{cur} [' + ', '.join([f'*{prev}'] * 9) + ']')
    return '\n'.join(lines) + '\nblocks: *' + chr(96 + levels) + '\n'


@pytest.mark.parametrize('text, limit', [
    (billion_laughs(), 'nodes with its aliases expanded'),
    ('blocks: ' + '[' * 5000 + ']' * 5000, 'nested more than 32 deep'),
    ('blocks:\n' + BLOCK * 200_000, f'more than the {MAX_BYTES} accepted'),
])
def test_costly_yaml_is_refused_quickly_naming_the_limit(text, limit):
    # CPU time of this process, not the wall clock (a busy computer must not fail it): unbounded, these inputs cost
    # minutes and gigabytes, orders of magnitude above the bound (bench_checks.py has the figures)
    t0 = time.process_time()
    with pytest.raises(ProgramError, match=limit):
        Program.from_yaml_text(text, name='hostile')
    assert time.process_time() - t0 < 0.5


def test_ordinary_anchors_aliases_and_the_largest_program_still_load():
    data = load_bounded('base: &b {waveform: sine, frequency: 2 Hz}\nother: {<<: *b, amplitude: 1 mm}\n')
    assert data['other'] == {'waveform': 'sine', 'frequency': '2 Hz', 'amplitude': '1 mm'}
    t0 = time.process_time()     # CPU time: a busy computer made the wall clock 5.009 s on CI once
    program = Program.from_yaml_text('blocks:\n' + BLOCK * MAX_BLOCKS)
    assert len(program.blocks) == MAX_BLOCKS and time.process_time() - t0 < 5.0
    with pytest.raises(ProgramError, match=f'more than {MAX_BLOCKS} blocks'):
        Program.from_yaml_text('blocks:\n' + BLOCK * (MAX_BLOCKS + 1))


def test_limits_are_counted_with_aliases_expanded():
    # 9 x 9 x 9 lists of 9 scalars: 7381 nodes expanded, under the limit; at level 9 it is 4.3e8
    assert len(load_bounded(billion_laughs(4))['d']) == 9
    with pytest.raises(YAMLLimitError, match='at most|more than 10 nodes'):
        load_bounded('[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11]', max_nodes=10)


def test_a_binary_or_oversized_program_file_is_refused_before_it_is_read(tmp_path):
    binary = tmp_path / 'prog.yaml'
    binary.write_bytes(b'\xff\xfe\x00blocks' * 10)
    with pytest.raises(ProgramError, match='not a text file'):
        read_program(str(binary))
    huge = tmp_path / 'huge.yaml'
    huge.write_text('blocks:\n' + BLOCK * 10_000)
    with pytest.raises(ProgramError, match='bytes, more than the'):
        read_program(str(huge))


def _read_in_thread(path):
    """read_program(path) in a daemon thread: (finished, exception). A FIFO that blocked would leave the thread
    waiting forever, so the test bounds the wait instead of hanging the suite (the read itself never sleeps)."""
    outcome = {}

    def work():
        try:
            read_program(str(path))
        except Exception as exc:  # noqa: BLE001 - the test inspects it
            outcome['exc'] = exc
    thread = threading.Thread(target=work, daemon=True)
    thread.start()
    thread.join(timeout=10.0)
    return not thread.is_alive(), outcome.get('exc')


@pytest.mark.parametrize('kind', ['dev_zero', 'fifo', 'directory', 'symlink_to_dev_zero'])
def test_a_program_path_that_is_not_a_regular_file_is_refused_without_reading_it(tmp_path, kind):
    if kind == 'dev_zero':
        path = '/dev/zero'                     # endless: read_text() grew the excitation to 1.76 GB
    elif kind == 'fifo':
        path = tmp_path / 'prog.yaml'
        os.mkfifo(path)                        # no writer: open() and read() would block for ever
    elif kind == 'directory':
        path = tmp_path / 'prog.yaml'
        path.mkdir()
    else:
        path = tmp_path / 'prog.yaml'
        path.symlink_to('/dev/zero')
    finished, exc = _read_in_thread(path)
    assert finished, f'reading {kind} did not return'
    assert isinstance(exc, ProgramError)
    assert 'only regular files are read' in str(exc) and str(path) in str(exc)
    expected = {'dev_zero': 'character device', 'fifo': 'FIFO', 'directory': 'directory',
                'symlink_to_dev_zero': 'character device'}[kind]
    assert expected in str(exc)


def test_a_file_that_grows_while_read_is_cut_at_the_limit(tmp_path, monkeypatch):
    # The size is checked on the opened file, then at most max_bytes + 1 bytes are read whatever the size
    # claimed: a file still being written (an fstat that says 10 bytes while it holds 6 kB) is cut at the limit.
    path = tmp_path / 'grows.yaml'
    path.write_text('blocks:\n' + BLOCK * 100)
    real_fstat = os.fstat

    class StillGrowing:
        def __init__(self, st):
            self.st_mode, self.st_size = st.st_mode, 10
    monkeypatch.setattr(os, 'fstat', lambda fd: StillGrowing(real_fstat(fd)))
    with pytest.raises(YAMLLimitError, match='grew past 200 bytes while read'):
        yamltext.read_bounded_file(path, 'program x', max_bytes=200)
    assert len(yamltext.read_bounded_file(path, 'program x', max_bytes=10_000)) == path.stat().st_size
