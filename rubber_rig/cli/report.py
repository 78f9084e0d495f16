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

"""Report on a recording: PNG figures and one self-contained HTML page, like seed 000's figures.

Examples:
  rubber-rig report run.mcap                         # fits the recording, then reports
  rubber-rig report run.mcap --fit params.yaml -o report_20C
  rubber-rig report run.mcap --fit rubber_rig/models/data/swing_arm_joint.yaml --set swing_arm_joint_20C
Figures: hysteresis loops measured vs model per block (Fig. 5/6), K_dyn and C_eq vs frequency per
amplitude (Fig. 4), R_K and R_E (Fig. 7), time traces with the force residual, errors per block.
Units in the figures: mm, kN, kN/mm, kN s/m (as in the papers).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path


def add_arguments(parser):
    parser.add_argument('recording', help='MCAP recording (file or split-file directory)')
    parser.add_argument('--fit', default=None, help='parameter YAML (written by rubber-rig fit, or a shipped set '
                        'file); without it the recording is fitted first')
    parser.add_argument('--set', default=None, help='parameter-set name in --fit (default: the one whose '
                        'temperature is nearest to the recording)')
    parser.add_argument('--output-dir', '-o', default=None, help='where to write (default: <recording>_report/)')
    parser.add_argument('--method', choices=('harmonic', 'time'), default='time',
                        help='fit method when no --fit is given (default time)')
    parser.add_argument('--settle-cycles', type=int, default=3, help='cycles skipped at the start of each block')
    parser.add_argument('--min-cycles', type=int, default=2, help='fewest analysed cycles for a block to count')
    parser.add_argument('--json', action='store_true', help='print the written files as JSON')


def _choose_set(sets, name, temperature, messages):
    if name is not None:
        if name not in sets:
            raise ValueError(f'no parameter set {name!r} in the file (it has: {", ".join(sorted(sets))})')
        return name
    if len(sets) == 1:
        return next(iter(sets))
    with_t = {k: v for k, v in sets.items() if v.get('temperature') is not None}
    if temperature is None or not with_t:
        raise ValueError(f'the file has several sets ({", ".join(sorted(sets))}); choose one with --set')
    best = min(with_t, key=lambda k: abs(with_t[k]['temperature'] - temperature))
    if abs(with_t[best]['temperature'] - temperature) > 0.5:
        messages.append(f'no set at {temperature:g} degC; using {best} ({with_t[best]["temperature"]:g} degC)')
    return best


def run(args) -> int:
    from rubber_rig.fitting.blocks import split_blocks
    from rubber_rig.fitting.data import load_run
    from rubber_rig.fitting.report import make_report
    run_data = load_run(args.recording)
    messages = list(run_data.messages)
    if not run_data.usable():
        raise ValueError('; '.join(messages) or f'{args.recording}: nothing to report on')
    rep = split_blocks(run_data.displacement, run_data.force, run_data.dt, block_index=run_data.block_index,
                       program_blocks=run_data.program_blocks, settle_cycles=args.settle_cycles,
                       min_cycles=args.min_cycles, recording=run_data.name)
    messages += rep.messages
    if not rep.blocks:
        raise ValueError(f'{args.recording}: no usable steady block; ' + '; '.join(messages))
    quality, info = None, {}
    if args.fit:
        from rubber_rig.fitting.paramfile import load_fit_file
        sets = load_fit_file(args.fit)
        name = _choose_set(sets, args.set, run_data.temperature, messages)
        params = sets[name]['values']
        info['source'] = f'{args.fit}, set {name}'
    else:
        from rubber_rig.fitting.pipeline import fit_runs
        fits, fit_messages = fit_runs([run_data], method=args.method, settle_cycles=args.settle_cycles,
                                      min_cycles=args.min_cycles)
        messages += fit_messages
        fit = fits[0]
        params, quality = fit.params, fit.quality
        info = {'source': f'fitted to this recording ({fit.method} method)',
                'relative_sigma': fit.uncertainty.get('relative_sigma')}
    outdir = Path(args.output_dir) if args.output_dir else Path(f'{Path(args.recording).with_suffix("")}_report')
    files = make_report(run_data, rep.blocks, params, outdir, quality=quality, param_info=info,
                        messages=messages)
    if args.json:
        json.dump({'files': {k: str(v) for k, v in files.items()}, 'messages': messages}, sys.stdout, indent=1)
        sys.stdout.write('\n')
    else:
        for m in messages:
            print(f'note: {m}')
        for k, v in files.items():
            print(f'{k:>9}: {v}')
    return 0
