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

"""Identify seed-000 model parameters from MCAP recordings (one table row per temperature).

Examples:
  rubber-rig fit run_20C.mcap run_m40C.mcap -o params.yaml
  rubber-rig fit run.mcap --method harmonic --w-k 100 --w-c 1 --json > fit.json
Each recording is split into blocks (recorded block index / program, or detected steady segments),
the first --settle-cycles cycles of each block are skipped, and K_dyn, loss angle, D, energy and C_eq
are measured per block. The fit minimises seed 000 Eq. 29 (differential evolution + least-squares
polish); --method time (default) then refines on the raw force-displacement loops. Recordings at the
same temperature (metadata or temperature channel, 0.5 degC bins) are fitted together. The
parameters are written as YAML in the format of rubber_rig/models/data/swing_arm_joint.yaml.
Tables print in the papers' units (mm, kN, kN/mm); YAML and --json are SI.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

PAPER_UNITS = {'k0': (1e-6, 'kN/mm'), 'k_inf': (1e-6, 'kN/mm'), 'tau': (1.0, 's'), 'alpha': (1.0, '-'),
               'x2': (1e3, 'mm'), 'f_fmax': (1e-3, 'kN')}


def add_arguments(parser):
    parser.add_argument('recordings', nargs='+', help='MCAP recordings (files or split-file directories)')
    parser.add_argument('--output', '-o', default='fit_params.yaml',
                        help='parameter YAML to write (default fit_params.yaml; "-" for none)')
    parser.add_argument('--method', choices=('harmonic', 'time'), default='time',
                        help='harmonic: Eq. 29 only; time (default): Eq. 29, then refined on the raw loops')
    parser.add_argument('--w-k', type=float, default=100.0, help='weight of the K_dyn errors in Eq. 29 (100)')
    parser.add_argument('--w-c', type=float, default=1.0, help='weight of the C_eq errors in Eq. 29 (1)')
    parser.add_argument('--settle-cycles', type=int, default=3, help='cycles skipped at the start of each block (3)')
    parser.add_argument('--min-cycles', type=int, default=2, help='fewest analysed cycles for a block to count (2)')
    parser.add_argument('--seed', type=int, default=0, help='random seed of differential evolution')
    parser.add_argument('--prefix', default='fit', help='parameter-set names: <prefix>_20C, <prefix>_m40C, ...')
    parser.add_argument('--temperature', type=float, default=None,
                        help='temperature [degC] of all recordings (overrides metadata/channel)')
    parser.add_argument('--json', action='store_true', help='machine-readable result on stdout (SI)')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar on stderr')


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


def load_runs(paths, temperature=None):
    """RunData for every readable recording, plus messages for those that are not."""
    from rubber_rig.fitting.data import load_run
    runs, messages = [], []
    for p in paths:
        try:
            run = load_run(p)
        except FileNotFoundError as exc:
            messages.append(str(exc))
            continue
        except ValueError as exc:     # RecordingError is a ValueError: malformed or truncated file
            messages.append(f'{p}: cannot be read: {exc}')
            continue
        if temperature is not None:
            run.temperature = float(temperature)
        runs.append(run)
    return runs, messages


def print_table(fits, out=None):
    from rubber_rig.fitting.identify import PARAM_NAMES
    out = out or sys.stdout
    head = ' '.join(f'{n + " [" + PAPER_UNITS[n][1] + "]":>16}' for n in PARAM_NAMES)
    print(f'{"T [degC]":>9} {head}', file=out)
    for f in fits:
        t = 'unknown' if f.temperature is None else f'{f.temperature:g}'
        vals = ' '.join(f'{f.params[n] * PAPER_UNITS[n][0]:>16.4g}' for n in PARAM_NAMES)
        print(f'{t:>9} {vals}', file=out)
        sig = f.uncertainty.get('relative_sigma', {})
        print(f'{"+-1sigma":>9} ' + ' '.join(f'{100 * sig.get(n, float("nan")):>15.2f}%' for n in PARAM_NAMES),
              file=out)
        if f.true_params:
            print(f'{"vs true":>9} ' + ' '.join(
                f'{100 * (f.params[n] / f.true_params[n] - 1):>+15.2f}%' for n in PARAM_NAMES), file=out)
    print(file=out)
    for f in fits:
        t = 'unknown temperature' if f.temperature is None else f'{f.temperature:g} degC'
        sk, sc = f.max_errors('simulated')
        ak, ac = f.max_errors('analytic')
        print(f'{t}: {len(f.blocks)} blocks from {", ".join(f.runs)}; method {f.method}; '
              f'Eq. 29 = {f.eq29:.3g}; {f.timings.get("total_s", float("nan")):.1f} s', file=out)
        print(f'  max |error| per block: K_dyn {100 * sk:.2f} %, C_eq {100 * sc:.2f} % (model run on the measured '
              f'displacement); analytic {100 * ak:.2f} %, {100 * ac:.2f} %', file=out)
        print(f'  {"f [Hz]":>7} {"x0 [mm]":>7} {"K_dyn [kN/mm]":>13} {"e_K [%]":>8} '
              f'{"C_eq [kN s/m]":>13} {"e_C [%]":>8}', file=out)
        for q in f.quality:
            e = q.get('simulated', q['analytic'])
            print(f'  {q["frequency"]:7.3g} {q["amplitude"] * 1e3:7.3g} {q["measured"]["k_dyn"] * 1e-6:13.4g} '
                  f'{100 * e["e_k"]:8.2f} {q["measured"]["c_eq"] * 1e-3:13.4g} {100 * e["e_c"]:8.2f}', file=out)


def run(args) -> int:
    from rubber_rig.fitting.paramfile import write_fit_file
    from rubber_rig.fitting.pipeline import fit_runs
    from rubber_rig.fitting.progress import ProgressBar
    runs, messages = load_runs(args.recordings, args.temperature)
    if not runs:
        raise ValueError('no readable recording: ' + '; '.join(messages))
    bar = ProgressBar(enabled=not args.no_progress and sys.stderr.isatty())
    try:
        fits, fit_messages = fit_runs(runs, method=args.method, w_k=args.w_k, w_c=args.w_c,
                                      settle_cycles=args.settle_cycles, min_cycles=args.min_cycles,
                                      seed=args.seed, progress=bar)
    finally:
        bar.close()
    messages += fit_messages
    for f in fits:
        messages += [f'{f.temperature} degC: {m}' for m in f.messages]
    written = None
    if args.output and args.output != '-':
        written = str(write_fit_file(args.output, fits, prefix=args.prefix,
                                     source=f'rubber-rig fit {" ".join(Path(p).name for p in args.recordings)}'))
    if args.json:
        out = {'fits': [f.as_dict() for f in fits], 'messages': messages, 'output': written}
        json.dump(_jsonable(out), sys.stdout, indent=1)
        sys.stdout.write('\n')
    else:
        print_table(fits)
        for m in messages:
            print(f'note: {m}')
        if written:
            print(f'parameters written to {written}')
    return 0
