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

"""Identify a rubber-element model from MCAP recordings or a K_dyn / C_eq table, with honest uncertainty.

Examples:
  rubber-rig fit run_20C.mcap run_m40C.mcap -o fit.yaml
  rubber-rig fit run.mcap --model zener_berg --model zener_berg_cubic      # rank two models (AIC/BIC)
  rubber-rig fit run.mcap --model my_bushing.yaml --load-cell-delay 0.2ms --json > fit.json
  rubber-rig fit table.csv --model pad                                     # from a K_dyn/C_eq table
  rubber-rig fit pad_run.mcap --per-block                                  # seed 004: per block + trend
--model takes a model file (rubber-rig models explains the format), a named model (rubber-rig models) or a
parameter set; default zener_berg (seed 000). Each recording is split into blocks; the fit searches the
model's first harmonics globally (seed 000 Eq. 29) and, with --method time (default), refines on the raw
loops with the load-cell delay as a parameter. Every number comes with a 1-sigma uncertainty and a 95 %
interval (the larger of the noise-based one, inflated by the lack of fit, and the jackknife over blocks,
linearised), chi2/dof against the load-cell noise the recording shows, and warnings: misfit, per-block
errors, systematic residual patterns, parameters the data cannot identify, an estimated load-cell delay.
The fitted model is written as a model file with the uncertainties beside the values (one file per
temperature). Tables print in the papers' units (mm, kN, kN/mm); YAML and --json are SI.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from rubber_rig.units import to_si


def add_arguments(parser):
    parser.add_argument('recordings', nargs='+', help='MCAP recordings (files or split-file directories) or '
                                                      'one CSV table of K_dyn and C_eq')
    parser.add_argument('--model', '-m', action='append', default=None, metavar='FILE|NAME',
                        help='model to fit: a model file, a named model or a parameter set (default zener_berg); '
                             'give several to rank them by BIC (AIC beside it); the lowest BIC is selected')
    parser.add_argument('--output', '-o', default='fit.yaml',
                        help='model file to write (default fit.yaml; several temperatures: fit_20C.yaml, ...; '
                             'several models: the selected one; "-" for none)')
    parser.add_argument('--method', choices=('harmonic', 'time'), default='time',
                        help='harmonic: Eq. 29 only; time (default): then refined on the raw loops')
    parser.add_argument('--load-cell-delay', default=None,
                        help='known load-cell delay (calibration), e.g. 0.2ms; default: the recording\'s rig '
                             'configuration, else 0')
    parser.add_argument('--load-cell-gain', type=float, default=None,
                        help='known load-cell gain (calibration: reading / true force); default: the '
                             'recording\'s rig configuration, else 1')
    parser.add_argument('--load-cell-gain-u', type=float, default=None,
                        help='standard uncertainty of the load-cell gain (calibration certificate; class 0.5: '
                             '0.0029); default: the recording\'s rig configuration (load_cell_gain_u)')
    parser.add_argument('--load-cell-delay-u', default=None,
                        help='standard uncertainty of the load-cell delay, e.g. 0.02ms; default: the recording\'s '
                             'rig configuration (load_cell_delay_u)')
    parser.add_argument('--displacement-gain-u', type=float, default=None,
                        help='standard uncertainty of the displacement transducer\'s gain (calibration '
                             'certificate); default: the recording\'s rig configuration (displacement_gain_u)')
    parser.add_argument('--temperature-u', default=None,
                        help='standard uncertainty of the temperature sensor, e.g. 0.5K; default: the recording\'s '
                             'rig configuration (temperature_u)')
    parser.add_argument('--estimate-delay', action='store_true',
                        help='fit the load-cell delay as a parameter (never below zero) instead of using the '
                             'declared one; for a load cell whose timing nobody measured (the fit then warns)')
    parser.add_argument('--no-delay-estimate', action='store_true', help=argparse.SUPPRESS)   # the default now
    parser.add_argument('--per-block', action='store_true',
                        help='seed 004: identify K1, K3 and the elliptic damping b per block and fit their '
                             'trend over frequency and amplitude (Eq. 7)')
    parser.add_argument('--w-k', type=float, default=100.0, help='weight of the K_dyn errors in Eq. 29 (100)')
    parser.add_argument('--w-c', type=float, default=1.0, help='weight of the C_eq errors in Eq. 29 (1)')
    parser.add_argument('--settle-cycles', type=int, default=3, help='cycles skipped at the start of each block (3)')
    parser.add_argument('--min-cycles', type=int, default=2, help='fewest analysed cycles for a block to count (2)')
    parser.add_argument('--seed', type=int, default=0, help='random seed of differential evolution')
    parser.add_argument('--temperature', type=float, default=None,
                        help='temperature [degC] of all recordings (overrides metadata/channel)')
    parser.add_argument('--json', action='store_true', help='machine-readable result on stdout (SI)')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar on stderr')


def check_arguments(args):
    if args.per_block and (args.model or args.method != 'time'):
        return '--per-block identifies seed 004 coefficients per block; it takes no --model or --method'
    tables = [p for p in args.recordings if str(p).lower().endswith('.csv')]
    if tables and len(args.recordings) > 1:
        return 'give either one CSV table or MCAP recordings, not both'
    return None


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (np.floating, float)):
        f = float(v)
        if math.isinf(f):        # an unbounded side of an interval (budget.interval_note says why): not null
            return 'inf' if f > 0 else '-inf'
        return f if math.isfinite(f) else None
    if isinstance(v, (np.integer, np.bool_)):
        return v.item()
    return v


def load_runs(paths, temperature=None):
    """RunData for every readable recording, plus messages for those that are not."""
    from rubber_rig.fitting.data import load_run, with_temperature
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
            run = with_temperature(run, override=temperature)
        runs.append(run)
    return runs, messages


def _t(temp):
    return 'unknown temperature' if temp is None else f'{temp:g} degC'


def print_fit(fit, out=None):
    from rubber_rig.fitting.modelfit import paper_unit
    from rubber_rig.fitting.report import budget_text
    out = out or sys.stdout
    print(f'{fit.model.name or "model"} at {_t(fit.temperature)}: {len(fit.blocks)} blocks from '
          f'{", ".join(fit.runs)}; method {fit.method}; {fit.timings.get("total_s", math.nan):.1f} s', file=out)
    for name, rec in (fit.temperature_records or {}).items():
        if rec.get('source'):
            other = (f'; metadata {rec["metadata"]:g} degC' if rec['source'] != 'metadata'
                     and rec.get('metadata') is not None else '')
            print(f'  temperature of {name}: {rec["value"]:.3g} degC from the {rec["source"]}{other}', file=out)
    truth = fit.truth or {}
    head = f'  {"parameter":18s} {"value":>12s} {"+-1 sigma":>11s} {"95 % interval":>27s} {"unit":>8s}'
    print(head + ('  vs true  in 95 %?' if truth else ''), file=out)
    for name, u in fit.uncertainty.items():
        f, unit = paper_unit(fit.model, name)
        lo, hi = u['interval_95']
        line = (f'  {name:18s} {u["value"] * f:12.5g} {u["sigma"] * f:11.3g} '
                f'{"[" + format(lo * f, ".5g") + ", " + format(hi * f, ".5g") + "]":>27s} {unit:>8s}')
        if name in truth:
            ok = lo <= truth[name] <= hi
            line += f'  {100 * (u["value"] / truth[name] - 1):+7.2f} %  {"yes" if ok else "NO"}'
        print(line, file=out)
    for name, u in fit.uncertainty.items():
        if u.get('interval_note'):
            print(f'  {name}: {u["interval_note"]}', file=out)
    budgets = [(n, budget_text(u, u['value'])) for n, u in fit.uncertainty.items() if u.get('budget')]
    if budgets:
        print('  uncertainty budget (1 sigma, % of value; GUM Type A and the declared calibrations, total = root sum '
              'of squares):', file=out)
        for name, text in budgets:
            print(f'    {name:18s} {text}', file=out)
    sigma = ', '.join(f'{v:.3g} N' for v in fit.noise.values()) or 'not measured'
    m = fit.misfit
    carried = ''
    if m.get('input_noise') is not None:
        carried = (' plus ' + ', '.join(f'{v:.3g} N' for v in m['input_noise'].values())
                   + ' carried from the displacement noise')
    # one misfit figure everywhere (report header, JSON, model file): the test's
    print(f'  {fit.misfit_summary} ({fit.n_points} points, load-cell noise {sigma}{carried}); '
          f'AIC {fit.aic:.1f}, BIC {fit.bic:.1f}', file=out)
    st = m.get('structure') if m else None
    if st:
        parts = [f'{k} x excitation frequency {st[f"harmonic_{k}"]["z"]:+.1f} sigma' for k in (1, 3)
                 if f'harmonic_{k}' in st]
        if st.get('whiteness'):
            w = st['whiteness']
            parts.append(f'lag-1 autocorrelation {w["lag1"]:+.3f} (noise {w["expected"]:+.3f}, {w["z"]:+.1f} sigma)')
        parts.append(f'{len(st["blocks"])} of {st["n_blocks"]} blocks misfit alone')
        print('  residual structure: ' + '; '.join(parts), file=out)
    sk, sc = fit.max_errors('simulated' if fit.method == 'time' else 'analytic')
    print(f'  max |error| per block: K_dyn {100 * sk:.2f} %, C_eq {100 * sc:.2f} %', file=out)
    lc = fit.load_cell
    if lc.get('delay') or lc.get('gain', 1.0) != 1.0:
        print(f'  load-cell calibration applied ({lc.get("calibration_source")}): delay '
              f'{1e3 * lc["delay"]:.3f} ms, gain {lc["gain"]:.5g}', file=out)
    for n in fit.notes:
        print(f'  note: {n}', file=out)
    for w in fit.warnings:
        print(f'  WARNING: {w}', file=out)
    if not fit.warnings:
        print('  no warnings: the model describes these data to their noise level', file=out)


def _out_path(base, fit, n_fits):
    base = Path(base)
    if n_fits == 1:
        return base
    from rubber_rig.fitting.paramfile import set_name
    return base.with_name(f'{base.stem}_{set_name(fit.temperature, "").lstrip("_")}{base.suffix or ".yaml"}')


def _write(fits, output, sources):
    from rubber_rig.fitting.fitwarnings import warning_dict
    from rubber_rig.fitting.misfit import misfit_record
    written = []
    if not output or output == '-':
        return written
    for f in fits:
        path = _out_path(output, f, len(fits))
        f.model.meta = {k: v for k, v in f.model.meta.items() if k not in ('description',)}
        if f.temperature is not None:
            f.model.meta['temperature'] = f.temperature
        f.model.meta['fit'] = {'recordings': f.runs, 'method': f.method, 'chi2_per_dof': f.chi2_per_dof,
                               'misfit_test': misfit_record(f.misfit),
                               'warnings': [warning_dict(w) for w in f.warnings], 'load_cell': f.load_cell}
        header = (f'# rubber-rig fit {" ".join(sources)}\n# SI units; sigma = 1 sigma, interval_95 = 95 % '
                  'interval (see rubber-rig fit --help)')
        f.model.dump(path, results=f.uncertainty, header=header)
        written.append(str(path))
    return written


def _per_block(args, runs, messages):
    from rubber_rig.fitting.blocktrend import fit_blocks, fit_trend, per_block_report
    from rubber_rig.fitting.identification import split_runs
    groups, msgs = split_runs(runs, args.settle_cycles, args.min_cycles)
    messages += msgs
    out = []
    for temp, items in groups.items():
        rows = fit_blocks([(run, blocks) for run, blocks, _ in items])
        trends = [fit_trend(rows, name) for name in ('K1', 'K3', 'b')]
        out.append({'temperature': temp, 'blocks': rows, 'trends': trends})
        if not args.json:
            print(f'{_t(temp)}:')
            print(per_block_report(rows, trends))
    if args.json:
        json.dump(_jsonable({'per_block': out, 'messages': messages}), sys.stdout, indent=1)
        sys.stdout.write('\n')
    else:
        for m in messages:
            print(f'note: {m}')
    return 0


def run(args) -> int:
    from rubber_rig.fitting.blas import set_blas_threads
    from rubber_rig.fitting.fitwarnings import warning_dict
    from rubber_rig.fitting.identification import compare_models, fit_model
    from rubber_rig.fitting.progress import ProgressBar
    from rubber_rig.fitting.table import fit_table
    set_blas_threads()     # one thread unless OPENBLAS_NUM_THREADS says otherwise (numpy may be loaded already)
    models = args.model or ['zener_berg']
    delay = None if args.load_cell_delay is None else to_si(args.load_cell_delay, 'time')
    delay_u = None if args.load_cell_delay_u is None else to_si(args.load_cell_delay_u, 'time')
    temp_u = None if args.temperature_u is None else to_si(args.temperature_u, 'temperature_difference')
    declared = {'displacement_gain_u': args.displacement_gain_u, 'temperature_u': temp_u}
    table = str(args.recordings[0]).lower().endswith('.csv')
    messages = []
    if not table:
        runs, messages = load_runs(args.recordings, args.temperature)
        if not runs:
            raise ValueError('no readable recording: ' + '; '.join(messages))
        if args.per_block:
            return _per_block(args, runs, messages)
    bar = ProgressBar(enabled=not args.no_progress and not args.json and sys.stderr.isatty())
    by_model = {}
    try:
        for model in models:
            if table:
                fits, msgs = fit_table(args.recordings[0], model, w_k=args.w_k, w_c=args.w_c, seed=args.seed,
                                       gain_u=args.load_cell_gain_u, delay_u=delay_u, **declared)
            else:
                fits, msgs = fit_model(runs, model, method=args.method, load_cell_delay=delay,
                                       load_cell_gain=args.load_cell_gain, estimate_delay=args.estimate_delay,
                                       load_cell_gain_u=args.load_cell_gain_u, load_cell_delay_u=delay_u,
                                       settle_cycles=args.settle_cycles, min_cycles=args.min_cycles, seed=args.seed,
                                       w_k=args.w_k, w_c=args.w_c, progress=bar, **declared)
            by_model[model] = fits
            messages += [m for m in msgs if m not in messages]
    finally:
        bar.close()
    comparison = compare_models(by_model) if len(by_model) > 1 else []
    selected = comparison[0]['selected'] if comparison else models[0]
    fits = by_model[selected]
    written = _write(fits, args.output, [Path(p).name for p in args.recordings])
    if args.json:
        first = fits[0]
        warnings = [dict(warning_dict(w), temperature=f.temperature) for f in fits for w in f.warnings]
        out = {'model': selected, 'parameters': first.parameters, 'uncertainty': first.uncertainty,
               'warnings': warnings, 'chi2_per_dof': first.chi2_per_dof, 'misfit': first.misfit,
               'misfit_summary': first.misfit_summary,
               'fits': [f.as_dict() for f in fits], 'comparison': comparison,
               'candidates': {m: [f.as_dict() for f in fl] for m, fl in by_model.items() if m != selected},
               'messages': messages, 'output': written}
        json.dump(_jsonable(out), sys.stdout, indent=1)
        sys.stdout.write('\n')
        return 0
    for mfits in by_model.values():
        for f in mfits:
            print_fit(f)
            print()
    for c in comparison:
        print(f'model comparison at {_t(c["temperature"])} (AIC = chi2 + 2k, BIC = chi2 + k ln n):')
        for r in c['ranking']:
            print(f'  {r["model"]:24s} k={r["n_params"]:2d} chi2/dof={r["chi2_per_dof"]:8.3g} '
                  f'dBIC={r["delta_bic"]:9.1f} dAIC={r["delta_aic"]:9.1f} BIC weight={r["bic_weight"]:.3f} '
                  f'warnings={r["warnings"]}')
        print(f'  {c["verdict"]}')
    for m in messages:
        print(f'note: {m}')
    for w in written:
        print(f'model written to {w}')
    return 0
