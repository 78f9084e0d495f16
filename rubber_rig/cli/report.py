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

"""Report on a recording: PNG figures and one self-contained HTML page that show where a model misfits.

Examples:
  rubber-rig report run.mcap                         # fits the recording (zener_berg), then reports
  rubber-rig report run.mcap --model my_bushing.yaml # fits that model first
  rubber-rig report run.mcap --fit fit.yaml -o report_20C           # a model file written by rubber-rig fit
  rubber-rig report run.mcap --fit rubber_rig/models/data/swing_arm_joint.yaml --set swing_arm_joint_20C
--fit takes a model file (any composite model; with the sigma, 95 % intervals and fit record that
rubber-rig fit writes, shown in the report) or a seed-000 parameter-set table (--set picks the set).
The model runs over the measured displacement exactly as the fit runs it, with the fit's load-cell
calibration and estimated delay. Figures: loops measured on the model with the residual under each
loop and the load-cell noise band (Fig. 5/6), K_dyn and C_eq vs frequency with error bars and the model
with its uncertainty band (Fig. 4), R_K and R_E (Fig. 7, fractional Zener + Berg only), time traces,
errors per block. The page lists the parameters with +-1 sigma and 95 % intervals, chi2/dof and the
fit's warnings. Units: mm, kN, kN/mm, kN s/m (as in the papers).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path


def add_arguments(parser):
    parser.add_argument('recording', help='MCAP recording (file or split-file directory)')
    parser.add_argument('--fit', default=None, help='model file (written by rubber-rig fit, or any model file) or '
                        'parameter-set YAML (a shipped set file); without it the recording is fitted first')
    parser.add_argument('--set', default=None, help='parameter-set name in a --fit parameter table (default: the '
                        'one whose temperature is nearest to the recording)')
    parser.add_argument('--model', '-m', default=None, metavar='FILE|NAME',
                        help='model to fit when no --fit is given (default zener_berg)')
    parser.add_argument('--output-dir', '-o', default=None, help='where to write (default: <recording>_report/)')
    parser.add_argument('--method', choices=('harmonic', 'time'), default='time',
                        help='fit method when no --fit is given (default time)')
    parser.add_argument('--settle-cycles', type=int, default=3, help='cycles skipped at the start of each block')
    parser.add_argument('--min-cycles', type=int, default=2, help='fewest analysed cycles for a block to count')
    parser.add_argument('--json', action='store_true', help='print the written files as JSON')


def check_arguments(args):
    if args.fit and args.model:
        return '--model is the model to fit when no --fit is given; --fit already names the model'
    return None


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


def _read_model(path, set_name, temperature, messages):
    """The ReportModel of --fit: a model file, or a set of a parameter-set table."""
    from rubber_rig.fitting.paramfile import load_fit_file
    from rubber_rig.fitting.report_model import parameter_set_model, read_model_file
    from rubber_rig.models.modelfile import is_model_file
    if is_model_file(path):
        if set_name is not None:
            raise ValueError(f'--set picks a set of a parameter table; {path} is a model file (one model)')
        model = read_model_file(path)
        t = model.spec.meta.get('temperature')
        if isinstance(t, (int, float)) and temperature is not None and abs(t - temperature) > 0.5:
            messages.append(f'the model was identified at {t:g} degC; the recording is at {temperature:g} degC')
        return model
    sets = load_fit_file(path)
    name = _choose_set(sets, set_name, temperature, messages)
    return parameter_set_model(sets[name]['values'], name, f'{path}, set {name}', sets[name]['temperature'])


def run(args) -> int:
    from rubber_rig.fitting.blocks import split_blocks
    from rubber_rig.fitting.data import load_run
    from rubber_rig.fitting.identification import fit_model
    from rubber_rig.fitting.report import make_report
    from rubber_rig.fitting.report_model import calibrated_run, model_from_fit
    run_data = load_run(args.recording)
    messages = list(run_data.messages)
    if not run_data.usable():
        raise ValueError('; '.join(messages) or f'{args.recording}: nothing to report on')
    if args.fit:
        model = _read_model(args.fit, args.set, run_data.temperature, messages)
        measured, calibration = calibrated_run(run_data, model)
        rep = split_blocks(measured.displacement, measured.force, measured.dt, block_index=measured.block_index,
                           program_blocks=measured.program_blocks, settle_cycles=args.settle_cycles,
                           min_cycles=args.min_cycles, recording=measured.name)
        messages += rep.messages
        blocks = rep.blocks
        if not blocks:
            raise ValueError(f'{args.recording}: no usable steady block; ' + '; '.join(messages))
    else:
        name = args.model or 'zener_berg'
        fits, fit_messages = fit_model([run_data], name, method=args.method, settle_cycles=args.settle_cycles,
                                       min_cycles=args.min_cycles)
        messages += [m for m in fit_messages if m not in messages]
        fit = fits[0]
        model = model_from_fit(fit, f'fitted to this recording ({name}, {fit.method} method)')
        measured, calibration = calibrated_run(run_data, model)
        blocks = fit.blocks
    outdir = Path(args.output_dir) if args.output_dir else Path(f'{Path(args.recording).with_suffix("")}_report')
    files = make_report(measured, blocks, model, outdir, messages=messages, calibration=calibration)
    if args.json:
        json.dump({'files': {k: str(v) for k, v in files.items()}, 'messages': messages}, sys.stdout, indent=1)
        sys.stdout.write('\n')
    else:
        for m in messages:
            print(f'note: {m}')
        for k, v in files.items():
            print(f'{k:>9}: {v}')
    return 0
