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

"""Detection delay and false trips of the detectors against their threshold, at 20 N and 200 N load-cell noise.

    .venv/bin/python benchmarks/bench_detectors.py            # everything (about 10 min on 2 cores)
    .venv/bin/python benchmarks/bench_detectors.py --quick    # the damage cases and one shipped program

The measurement is the nodes' own pipeline without ROS in between: the simulated rig (unpaced, same physics and
noise) runs the program with amplitude control and the specimen's damage, the element model's OnlinePredictor
predicts every sample in 10 ms batches, the CyclePairer cuts and pairs the cycles per block, and the excitation's
Monitor judges each one (``cycle_of`` places it in the program as the node does). Every threshold of the sweep
is a separately named detector of one Monitor, so all see the same cycles. The node test
(test/test_detectors_nodes.py) measures the same through separate processes, with the action taken.

Damage cases, in a 300-cycle, 1 mm, 10 Hz block (durability_10hz shortened): a crack (30 % stiffness) at
specimen cycle 150, a smaller crack (10 %), fatigue (40 % loss over 100 cycles from cycle 100: the 20 % end of
life at cycle 150) and a 0.2 mm fixture slip at cycle 150. Delay: from the onset (the crack or slip cycle; for
fatigue the cycle where the loss reaches the threshold) to the end of the cycle the detector tripped on, in
cycles; 'missed' when it never tripped. False trips: trips over the clean shipped programs (every block, all
thresholds, and the default detector set), counted once per detector and block.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from rubber_rig.excitation import ProgramRunner  # noqa: E402
from rubber_rig.excitation.detector_specs import DEFAULTS, parse_detectors  # noqa: E402
from rubber_rig.excitation.detectors import Monitor, cycle_of  # noqa: E402
from rubber_rig.excitation.program import load_program, shipped_programs, with_overrides  # noqa: E402
from rubber_rig.online import CyclePairer, ModelChoice, OnlinePredictor, cycle_properties  # noqa: E402
from rubber_rig.rig.options import DamageSpec  # noqa: E402
from rubber_rig.rig.sim.damage import sample_at_cycle  # noqa: E402
from rubber_rig.session import run_program  # noqa: E402

REVERSAL_THRESHOLD = 2e-6    # [m] as config/rig_sim.yaml (specimen and element_model)
BATCH = 10                   # samples per prediction batch (rig_driver: 10 ms at 1 kHz)
NOISES = (20.0, 200.0)       # [N] load-cell noise, standard deviation
RESIDUAL_K = (2.0, 3.0, 4.0, 6.0, 8.0)
STIFFNESS_X = (0.05, 0.1, 0.2, 0.3)
DAMAGE = {
    'crack 30 %': {'type': 'crack', 'cycle': 150, 'loss': 0.3},
    'crack 10 %': {'type': 'crack', 'cycle': 150, 'loss': 0.1},
    'fatigue 40 %/100 cycles': {'type': 'fatigue', 'cycle': 100, 'loss': 0.4, 'life': 100},
    'slip 0.2 mm': {'type': 'slip', 'cycle': 150, 'offset': -0.2e-3},
}


def sweep() -> list:
    """One detector per threshold (names say which), plus the defaults under their own names."""
    raw = [{'name': f'residual k={k:g}', 'type': 'residual', 'threshold': k} for k in RESIDUAL_K]
    raw += [{'name': f'stiffness {x:.0%}', 'type': 'stiffness_change', 'threshold': x} for x in STIFFNESS_X]
    raw += [dict(d, name='default ' + d['type']) for d in DEFAULTS]
    return parse_detectors(raw, 'bench_detectors')


def config(noise: float, damage: dict | None) -> dict:
    sim = {'specimen': {'parameter_set': 'swing_arm_joint_20C', 'friction_reversal_threshold': REVERSAL_THRESHOLD},
           'force_noise': noise, 'damage': [damage] if damage else []}
    return {'paced': False, 'sample_rate': 1000.0, 'sim': sim}


def judge(program, noise: float, damage: dict | None, seed: int = 0):
    """Run `program` on the simulated rig and replay it through the online pipeline: (Monitor, RunResult)."""
    np.random.seed(seed)
    r = run_program(program, config(noise, damage), amplitude_control=True)
    fs = r.sample_rate
    runner = ProgramRunner(program, fs, check_program=False)       # open loop: same blocks, same sequences
    runner.next_setpoints(program.n_samples(fs) + 1)
    predictor = OnlinePredictor(ModelChoice(friction_reversal_threshold=REVERSAL_THRESHOLD))
    pairer = CyclePairer(min_amplitude=5e-6)
    monitor = Monitor(sweep())
    seq0 = int(r.sequence[0])
    for i in range(0, r.sequence.size, BATCH):
        sl = slice(i, i + BATCH)
        predicted, _ = predictor.process(int(r.sequence[i]), 1 / fs, r.displacement[sl])
        blocks = r.block_index[sl]
        cuts = np.flatnonzero(np.diff(blocks)) + 1
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, blocks.size], strict=True):
            first = int(r.sequence[i + a])
            for c in pairer.feed(first, 1 / fs, r.displacement[sl][a:b], r.force[sl][a:b], predicted[a:b],
                                 int(blocks[a])):
                m = c.measured
                cyc = cycle_of(runner, c.start_sequence, c.end_sequence, m['amplitude'], m['peak_amplitude'],
                               m['mean'], cycle_properties(m), cycle_properties(c.model), c.residual_rms,
                               (c.end_sequence - seq0) / fs)
                if cyc is not None:
                    monitor.on_cycle(cyc)
    return monitor, r


def onset_sample(r, damage: dict, threshold: float = None) -> int:
    """Sample index where the specimen (counting its own reversals as the simulator does) reaches the onset."""
    spec = DamageSpec(**damage)
    n = spec.cycle
    if spec.type == 'fatigue' and threshold is not None:
        n = spec.cycle + spec.life * (threshold / spec.loss) ** (1 / spec.exponent)
    return sample_at_cycle(r.displacement, n)     # the measured displacement: noise 0.2 um << 10 um


def delays(monitor, r, damage: dict, period: int) -> dict:
    """{detector: delay in cycles (end of the tripping cycle - onset) or None (missed)}; the trips before the
    onset are false trips (value 'early').
    """
    out = {}
    for d in monitor.detectors:
        if d.type in ('cycle_count', 'elapsed_time'):
            continue
        threshold = d.threshold if d.type == 'stiffness_change' else None
        onset = onset_sample(r, damage, threshold)
        trips = [e for e in monitor.events if e.detector == d.name]
        if not trips:
            out[d.name] = None
            continue
        end = trips[0].elapsed * r.sample_rate
        out[d.name] = 'early' if end < onset else (end - onset) / period
    return out


def damage_table(noises, out: dict) -> None:
    program, _ = with_overrides(load_program('durability_10hz'), cycles=300, note='bench_detectors')
    program.detectors = []
    period = 100                         # samples per cycle at 10 Hz and 1 kHz
    for noise in noises:
        for case, damage in DAMAGE.items():
            t0 = time.perf_counter()
            monitor, r = judge(program, noise, damage)
            if not r.completed:
                raise RuntimeError(f'{case} at {noise:g} N: the rig ended the run early: {r.message}')
            d = delays(monitor, r, damage, period)
            out.setdefault('damage', []).append({'noise': noise, 'case': case, 'delays': d})
            cells = ', '.join(f'{k}: ' + ('missed' if v is None else v if isinstance(v, str) else f'{v:.2f}')
                              for k, v in d.items())
            print(f'  {noise:5.0f} N  {case:24s} {cells}  ({time.perf_counter() - t0:.0f} s)', flush=True)


def false_trips(noises, programs, out: dict) -> None:
    for noise in noises:
        for name in programs:
            t0 = time.perf_counter()
            program = load_program(name)
            monitor, r = judge(program, noise, None)
            counts = {d.name: sum(e.detector == d.name for e in monitor.events) for d in monitor.detectors}
            out.setdefault('false_trips', []).append({'noise': noise, 'program': name, 'blocks':
                                                      len(program.blocks), 'trips': counts, 'peak': monitor.peak,
                                                      'completed': r.completed, 'message': r.message,
                                                      'events': [e.message for e in monitor.events
                                                                 if e.detector.startswith('default')]})
            tripped = {k: v for k, v in counts.items() if v}
            # a run the rig ended early judged fewer cycles: its trip count is not a false-trip rate
            ran = 'completed' if r.completed else f'INCOMPLETE ({r.message})'
            print(f'  {noise:5.0f} N  {name:16s} {len(program.blocks):3d} blocks {r.sequence.size / 1000:6.0f} s  '
                  f'{ran}  trips: {tripped or "none"}  ({time.perf_counter() - t0:.0f} s)', flush=True)


def markdown(out: dict) -> str:
    names = [d.name for d in sweep()]
    lines = ['### Detection delay [cycles after the onset] in a 10 Hz, 1 mm block', '',
             '| noise | damage | ' + ' | '.join(names) + ' |', '|' + '---|' * (len(names) + 2)]
    for row in out.get('damage', []):
        cells = [('missed' if row['delays'].get(n) is None else row['delays'][n]
                  if isinstance(row['delays'][n], str) else f"{row['delays'][n]:.2f}") for n in names]
        lines.append(f"| {row['noise']:.0f} N | {row['case']} | " + ' | '.join(cells) + ' |')
    lines += ['', '### False trips over the clean shipped programs (blocks with a trip)', '',
              '| noise | program | blocks | run | ' + ' | '.join(names) + ' |', '|' + '---|' * (len(names) + 4)]
    for row in out.get('false_trips', []):
        lines.append(f"| {row['noise']:.0f} N | {row['program']} | {row['blocks']} | "
                     f"{'completed' if row['completed'] else 'ENDED EARLY'} | "
                     + ' | '.join(str(row['trips'].get(n, 0)) for n in names) + ' |')
    lines += ['', '### Margin: the largest fraction of its threshold a clean cycle reached (1.00 trips)', '',
              '| noise | ' + ' | '.join(names) + ' |', '|' + '---|' * (len(names) + 1)]
    for noise in sorted({row['noise'] for row in out.get('false_trips', [])}):
        rows = [row for row in out['false_trips'] if row['noise'] == noise]
        lines.append(f'| {noise:.0f} N | ' + ' | '.join(
            f"{max(row['peak'].get(n, 0.0) for row in rows):.2f}" for n in names) + ' |')
    return '\n'.join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--quick', action='store_true', help='damage cases and dynamic_stiffness_grid only')
    ap.add_argument('--json', help='write the results here')
    args = ap.parse_args(argv)
    out = {}
    t0 = time.perf_counter()
    print('detection delay [cycles after onset] (durability_10hz, 300 cycles):')
    damage_table(NOISES, out)
    programs = ['dynamic_stiffness_grid'] if args.quick else [p for p in shipped_programs() if p != 'durability_10hz']
    print('false trips over the clean shipped programs:')
    false_trips(NOISES, programs, out)
    print()
    print(markdown(out))
    print(f'\n({time.perf_counter() - t0:.0f} s)')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(out, f, indent=1, default=lambda v: None if isinstance(v, float) and math.isnan(v) else v)
    return 0


if __name__ == '__main__':
    sys.exit(main())
