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
import time

import pytest

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
    t0 = time.perf_counter()
    with pytest.raises(ProgramError, match=limit):
        Program.from_yaml_text(text, name='hostile')
    assert time.perf_counter() - t0 < 0.5


def test_ordinary_anchors_aliases_and_the_largest_program_still_load():
    data = load_bounded('base: &b {waveform: sine, frequency: 2 Hz}\nother: {<<: *b, amplitude: 1 mm}\n')
    assert data['other'] == {'waveform': 'sine', 'frequency': '2 Hz', 'amplitude': '1 mm'}
    t0 = time.perf_counter()
    program = Program.from_yaml_text('blocks:\n' + BLOCK * MAX_BLOCKS)
    assert len(program.blocks) == MAX_BLOCKS and time.perf_counter() - t0 < 5.0
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
    with pytest.raises(ProgramError, match='bytes, more than'):
        read_program(str(huge))
