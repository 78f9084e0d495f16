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
"""The bench's per-block table and summary files, without ROS: cycle metrics in, rows and files out."""
import json
import math
from types import SimpleNamespace

import pytest

from rubber_rig.cli.bench import save_summary
from rubber_rig.excitation import Program
from rubber_rig.online.summary import BlockTable, write_summary

PROGRAM = Program.from_yaml_text(
    'name: t\nblocks:\n'
    '  - {name: s, waveform: sine, frequency: 4 Hz, amplitude: 1 mm, cycles: 8}\n'
    '  - {name: w, waveform: sweep_log, f_start: 1 Hz, f_end: 10 Hz, duration: 20 s, amplitude: 0.5 mm}\n'
    '  - {name: h, waveform: hold, duration: 1 s}\n')

SUMMARY = {'program': 't', 'recording': 'run.mcap', 'wall_time_s': 3.5,
           'rig': {'backend': 'sim', 'sample_rate': 1000.0, 'paced': False, 'specimen': 'x'},
           'model': {'source': 'parameter_set', 'parameter_set': 'swing_arm_joint_20C', 'values': {'k0': 1.2e7}},
           'result': {'message': 'completed'},
           'loss': {'live': {'samples': {'samples': 100, 'gaps': 0}, 'prediction': {'samples': 100, 'gaps': 0}},
                    'recording': {'samples_lost': 0}},
           'latency': {}, 'blocks': []}


def cycle(block, i, f, amplitude, k_meas, k_model, c_meas=2e5, c_model=2.1e5):
    side = lambda k, c: SimpleNamespace(k_dyn=k, loss_angle=0.1, damping=0.1, c_eq=c,  # noqa: E731
                                        energy_harmonic=1.0, energy_loop=1.0)
    return SimpleNamespace(block_index=block, cycle_index=i, frequency=f, amplitude=amplitude,
                           peak_amplitude=amplitude, mean=0.0, measured=side(k_meas, c_meas),
                           model=side(k_model, c_model))


def test_a_periodic_block_averages_the_second_half_of_its_full_amplitude_cycles():
    t = BlockTable(PROGRAM)
    # taper cycles (small amplitude) and the first half of the steady ones are left out
    cycles = [cycle(0, 0, 4.0, 0.3e-3, 1e7, 1e7)] + [cycle(0, i, 4.0, 1e-3, 14e6 + i * 1e5, 14.7e6)
                                                     for i in range(1, 9)]
    done = []
    for c in cycles:
        done += t.add(c)
    assert done == []                                  # block 0 is complete only once block 1 starts
    assert t.add(cycle(1, 0, 1.0, 0.5e-3, 1e7, 1e7)) == [0]
    (row,) = t.row_list(0)
    assert row['cycles_used'] == 4
    k = sum(14e6 + i * 1e5 for i in range(5, 9)) / 4
    assert row['measured']['k_dyn'] == pytest.approx(k)
    assert row['deviation_k_dyn_pct'] == pytest.approx(100 * (14.7e6 / k - 1))
    assert row['deviation_c_eq_pct'] == pytest.approx(5.0)
    assert t.format(0)[0].split()[:3] == ['0', 's', '4.00'] and 0 in t.printed


def test_a_sweep_gets_one_row_per_frequency_band_and_a_hold_none():
    t = BlockTable(PROGRAM)
    for i, f in enumerate((1.0, 1.05, 1.5, 2.0, 2.9, 3.1, 4.0, 5.0, 7.2, 10.0)):
        t.add(cycle(1, i, f, 0.5e-3, 1e7 * f, 1e7 * f))
    rows = t.row_list(1)
    assert [r['name'] for r in rows] == ['w @1Hz', 'w @1.5Hz', 'w @2Hz', 'w @3Hz', 'w @5Hz', 'w @7Hz', 'w @10Hz']
    assert rows[0]['frequency'] == pytest.approx(1.025) and rows[0]['cycles_used'] == 2
    assert t.row_list(2) == []


def test_summary_files_hold_the_rows(tmp_path):
    t = BlockTable(PROGRAM)
    for i in range(1, 9):
        t.add(cycle(0, i, 4.0, 1e-3, 14e6, 14.7e6))
    rows = t.row_list(0)
    summary = {**SUMMARY, 'blocks': rows}
    jpath, mpath = write_summary(tmp_path / 'run.mcap', summary)
    assert json.loads(jpath.read_text())['blocks'][0]['measured']['k_dyn'] == pytest.approx(14e6)
    md = mpath.read_text()
    assert '| 0 | s | 4.00 | 1.000 | 1.000 | 14.000 | 14.700 | +5.00 |' in md
    assert f"{math.degrees(0.1):.2f} / {math.degrees(0.1):.2f}" in md


def test_a_summary_that_cannot_be_written_is_printed_instead(tmp_path, capsys):
    summary = {**SUMMARY, 'wall_time_s': 1.5}
    missing = tmp_path / 'gone' / 'run.mcap'           # its directory does not exist: the write fails
    assert save_summary(missing, summary) == (None, None, f'cannot write the summary next to {missing}: '
                                                          'No such file or directory')
    assert json.loads(capsys.readouterr().out) == summary
    jpath, mpath, error = save_summary(tmp_path / 'run.mcap', SUMMARY)
    assert error == '' and jpath.name == 'run.summary.json' and mpath.name == 'run.summary.md'
    assert '- result: completed in 3.5 s wall time' in mpath.read_text()
