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

"""Detection table: which detector fires, how late, with which action and cause label, for specimen damage, a
wrong model and load-cell faults; and the false trips of a long clean run.

    .venv/bin/python benchmarks/bench_detector_causes.py            # about 10 min on 2 cores
    .venv/bin/python benchmarks/bench_detector_causes.py --quick    # the fault scenarios only (about 30 s)

ROS-free: the simulated rig (unpaced, the specimen's damage and the controller's stuck load cell are its own)
runs a 10 Hz sine; load-cell offset jumps, saturation and spikes are applied to the force record
(rubber_rig.rig.sim.load_cell: in displacement control the reading does not act back); the element model's
OnlinePredictor and CyclePairer make the cycles and the excitation's Monitor judges them with the default
detector set (rubber_rig.session.cycle_stream). Each scenario is judged twice: with the defaults, and with the
defaults less model_fit and load_cell (what the detectors did before them, 'before' columns).

Delay: from the onset (the fault's start; for damage the specimen's own cycle count, as bench_detectors) to the
end of the cycle the event was raised on, in cycles. False trips: events before the onset, or events whose
cause is not the scenario's (a record-only event counts too). The clean runs: a 10 Hz sine of 3000 cycles (20 and
200 N noise, and with the 0 degC model: its mismatch event is expected), test_detectors_nodes' three-block
program and the shipped programs it runs, at 200 N.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from rubber_rig.excitation.detector_specs import DEFAULTS, parse_detectors  # noqa: E402
from rubber_rig.excitation.detectors import Monitor  # noqa: E402
from rubber_rig.excitation.program import load_program, read_program  # noqa: E402
from rubber_rig.rig.options import DamageSpec  # noqa: E402
from rubber_rig.rig.sim.damage import sample_at_cycle  # noqa: E402
from rubber_rig.rig.sim.load_cell import LoadCellFault  # noqa: E402
from rubber_rig.session.cycle_stream import simulate  # noqa: E402

FREQUENCY = 10.0
ONSET = 60                   # cycle (or the time of it) the fault starts in a 120-cycle run
T_ON = ONSET / FREQUENCY + 0.0055    # [s] a load-cell fault starts mid-cycle (not on a cycle boundary)
COLD = 'swing_arm_joint_0C'
# (name, expected cause, amplitude, simulate keyword arguments)
SCENARIOS = [
    ('right model, tear 15 %', 'specimen', '1 mm', {'damage': [{'type': 'crack', 'cycle': ONSET, 'loss': 0.15}]}),
    ('0 degC model on 20 degC specimen', 'model', '1 mm', {'model': COLD}),
    ('0 degC model, tear 15 %', 'specimen', '1 mm',
     {'model': COLD, 'damage': [{'type': 'crack', 'cycle': ONSET, 'loss': 0.15}]}),
    ('+500 N load-cell jump, 1 mm', 'sensor', '1 mm', {'load_cell': LoadCellFault('offset_jump', T_ON, 500.0)}),
    ('+500 N load-cell jump, 0.3 mm', 'sensor', '0.3 mm', {'load_cell': LoadCellFault('offset_jump', T_ON, 500.0)}),
    ('stuck load cell', 'sensor', '1 mm', {'load_cell': LoadCellFault('stuck', T_ON)}),
    ('stuck load cell, the simulated controller\'s fault', 'sensor', '1 mm',
     {'faults': [{'type': 'stuck_sensor', 'sensor': 'force', 'start': T_ON}]}),
    ('load cell saturated at 12 kN', 'sensor', '1 mm', {'load_cell': LoadCellFault('saturation', T_ON, limit=12e3)}),
    ('spikes 8 kN every 0.517 s', 'sensor', '1 mm', {'load_cell': LoadCellFault('spikes', T_ON, 8e3, period=0.517)}),
    ('crack 30 %', 'specimen', '1 mm', {'damage': [{'type': 'crack', 'cycle': ONSET, 'loss': 0.3}]}),
    ('fixture slip 0.2 mm', 'fixture', '1 mm', {'damage': [{'type': 'slip', 'cycle': ONSET, 'offset': -0.2e-3}]}),
    ('fatigue 40 %/100 cycles', 'specimen', '1 mm',
     {'damage': [{'type': 'fatigue', 'cycle': ONSET, 'loss': 0.4, 'life': 100}]}),
]
PROGRAM = "name: causes\nblocks:\n  - {name: sine, waveform: sine, amplitude: %s, frequency: 10 Hz, cycles: %d}\n"


def monitors():
    """(the default detectors, the defaults without model_fit and load_cell)."""
    full = parse_detectors(list(DEFAULTS), 'default_detectors')
    return Monitor(full), Monitor([d for d in full if d.type not in ('model_fit', 'load_cell')])


def onset_time(r, force, kw) -> float:
    """[s] from the first sample: the fault's start, the damage cycle's sample or the first stuck sample."""
    if kw.get('damage'):
        return sample_at_cycle(r.displacement, DamageSpec(**kw['damage'][0]).cycle) / r.sample_rate
    if kw.get('faults'):
        moving = np.flatnonzero(np.diff(force) != 0)
        return (moving[-1] + 1) / r.sample_rate if moving.size else 0.0
    if kw.get('load_cell'):
        return kw['load_cell'].start
    return 0.0          # the model mismatch: there from the start, judged on the first steady cycles


def judge(name, cause, amplitude, kw, cycles=2 * ONSET, noise=20.0, program=None) -> dict:
    if program is None:
        program, _ = read_program(yaml_text=PROGRAM % (amplitude, cycles + 80 * ('fatigue' in name)))
    r, force, stream = simulate(program, noise=noise, **kw)
    t_on = onset_time(r, force, kw) if kw.get('damage') or kw.get('faults') or kw.get('load_cell') else None
    row = {'scenario': name, 'noise': noise, 'expected': cause}
    for label, monitor in zip(('now', 'before'), monitors(), strict=True):
        for c in stream:
            monitor.on_cycle(c)
        events = monitor.events
        expected = {cause, 'model'} if kw.get('model') == COLD else {cause}
        early = [e for e in events if t_on is not None and e.elapsed < t_on and e.cause not in expected]
        right = [e for e in events if e not in early and e.cause in expected]
        if cause != 'model':          # the mismatch is expected, the first event of the scenario's own cause counts
            right.sort(key=lambda e: e.cause == 'model')
        wrong = [e for e in events if e not in early and e not in right]
        first = right[0] if right else None
        delay = None if first is None else (first.elapsed - (t_on or 0.0)) * FREQUENCY
        if not r.completed and first is None:       # the rig ended the run itself (its own sensor check)
            first_rig = f'rig: {r.message[:60]}'
        else:
            first_rig = ''
        row[label] = {'rig': first_rig, 'fired': f'{first.detector} ({first.kind})' if first else 'nothing',
                      'delay': delay, 'action': first.action if first else '-',
                      'cause': (f'{first.cause}/{first.code}' if first.code else first.cause) if first else '-',
                      'false': len(early) + len(wrong),
                      'others': [f'{e.detector}:{e.cause}' for e in wrong + early]}
        if row.get('expected') == 'model' and label == 'now':
            row['model_fit'] = monitor.fit
    return row


def clean(cycles: int, noise: float, model='swing_arm_joint_20C') -> dict:
    return judge(f'no fault, {cycles} cycles, {noise:g} N noise' + ('' if model.endswith('20C') else ', 0 degC model'),
                 None, '1 mm', {'model': model}, cycles=cycles, noise=noise)


# test_detectors_nodes' clean program, and the shipped programs it runs (whole, amplitude control, 200 N noise)
THREE_BLOCKS = """name: clean
blocks:
  - {name: a, waveform: sine, frequency: 10 Hz, amplitude: 1 mm, cycles: 40}
  - {name: b, waveform: triangle, frequency: 2 Hz, amplitude: 0.5 mm, cycles: 8}
  - {name: c, waveform: sine, frequency: 14 Hz, amplitude: 0.2 mm, cycles: 40}
"""
SHIPPED = ('dynamic_stiffness_grid', 'quasi_static_then_sine', 'log_sweeps_1_50hz', 'preload_sine_grid')


def clean_programs(rows: list, noise: float = 200.0) -> None:
    programs = [('three blocks (test_detectors_nodes)', read_program(yaml_text=THREE_BLOCKS)[0])]
    programs += [(name, load_program(name)) for name in SHIPPED]
    for name, program in programs:
        rows.append(judge(f'no fault, {name}, {noise:g} N noise', None, '', {}, noise=noise, program=program))
        print(f"  {rows[-1]['scenario']}: {cell(rows[-1], 'now')}", flush=True)


def cell(row, label) -> str:
    r = row[label]
    delay = '-' if r['delay'] is None else f"{r['delay']:.2f}"
    extra = f" ({', '.join(r['others'])})" if r['others'] else ''
    if r['rig']:
        extra += f"; {r['rig']}"
    return f"{r['fired']} | {delay} | {r['action']} | {r['cause']} | {r['false']}{extra}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--quick', action='store_true', help='the fault scenarios only, no long clean runs')
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    for name, cause, amplitude, kw in SCENARIOS:
        rows.append(judge(name, cause, amplitude, kw))
        print(f"  {name}: {cell(rows[-1], 'now')}", flush=True)
    if not args.quick:
        for noise in (20.0, 200.0):
            rows.append(clean(3000, noise))
            print(f"  {rows[-1]['scenario']}: {cell(rows[-1], 'now')}", flush=True)
        rows.append(clean(3000, 20.0, COLD))
        print(f"  {rows[-1]['scenario']}: {cell(rows[-1], 'now')}", flush=True)
        clean_programs(rows)
        for name, cause, amplitude, kw in SCENARIOS[3:5] + SCENARIOS[-2:-1]:
            rows.append(judge(name + ', 200 N noise', cause, amplitude, kw, noise=200.0))
            print(f"  {rows[-1]['scenario']}: {cell(rows[-1], 'now')}", flush=True)
    head = 'fired | delay [cycles] | action | cause | false trips'
    print(f'\n| scenario | {head} | before: {head} |')
    print('|---|' + '---|' * 10)
    for row in rows:
        print(f"| {row['scenario']} | {cell(row, 'now')} | {cell(row, 'before')} |")
    print(f'\n({time.perf_counter() - t0:.0f} s; 10 Hz sine, 20 N load-cell noise unless stated, onset at cycle '
          f'{ONSET}; the expected cause of each: specimen, model, sensor or fixture as named)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
