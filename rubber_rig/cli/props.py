"""Steady-state properties of a rubber-element model: K_dyn, loss angle, D, C_eq, energy, R_K, R_E.

Examples:
  rubber-rig props --parameter-set seed000_20C --frequency 0.5Hz 4Hz 14Hz --amplitude 0.5mm 1mm
  rubber-rig props --temperature -10 --frequency-grid 0.5 14 8 --amplitude 1mm --json
  rubber-rig props --parameter-set seed000_m40C --frequency 4 --amplitude 0.5mm --method time
Output in SI (N/m, N s/m, J; loss_angle in rad in JSON, in degrees in the table).
"""
from __future__ import annotations

import json
import math

import numpy as np

from .units import parse_quantity

KEYS = ('frequency', 'amplitude', 'k_dyn', 'loss_angle', 'damping', 'c_eq', 'energy', 'r_k', 'r_e')


def add_arguments(parser):
    src = parser.add_mutually_exclusive_group()
    src.add_argument('--parameter-set', '-p', default=None,
                     help='named parameter set (default seed000_20C); see --list')
    src.add_argument('--temperature', '-T', default=None,
                     help='seed-000 parameters interpolated at this temperature [degC] (Table 1 range -40..20), '
                          'e.g. -10 or --temperature=-10degC')
    parser.add_argument('--list', action='store_true', help='list the parameter sets and exit')
    parser.add_argument('--frequency', '-f', nargs='+', default=None,
                        help='excitation frequencies [Hz], unit suffixes welcome (0.5Hz, 1kHz)')
    parser.add_argument('--frequency-grid', nargs=3, metavar=('START', 'STOP', 'N'), default=None,
                        help='N log-spaced frequencies from START to STOP')
    parser.add_argument('--amplitude', '-a', nargs='+', default=['1mm'],
                        help='displacement amplitudes [m], unit suffixes welcome (0.5mm); default 1mm')
    parser.add_argument('--method', choices=('analytic', 'time'), default='analytic',
                        help='closed forms (seed 000 Eq. 11-30) or a time-domain steady-state run')
    parser.add_argument('--rate', default='1kHz', help='sample rate of --method time (default 1kHz)')
    parser.add_argument('--scheme', default='default', choices=('default', 'paper', 'gl'),
                        help='fractional scheme of --method time (default: sum of exponentials)')
    parser.add_argument('--cycles', type=int, default=30, help='cycles simulated by --method time (last 2 analysed)')
    parser.add_argument('--json', action='store_true', help='print a JSON list of objects instead of a table')


def _spec(args):
    if args.temperature is not None:
        return {'model': 'seed000', 'temperature': parse_quantity(args.temperature, 'temperature')}
    return {'parameter_set': args.parameter_set or 'seed000_20C'}


def _frequencies(args):
    if args.frequency_grid is not None:
        lo, hi = (parse_quantity(v, 'frequency') for v in args.frequency_grid[:2])
        n = int(args.frequency_grid[2])
        if n < 1 or lo <= 0 or hi <= 0:
            raise ValueError('--frequency-grid needs START, STOP > 0 Hz and N >= 1')
        return list(np.geomspace(lo, hi, n))
    values = args.frequency or ['0.5Hz', '1Hz', '2Hz', '4Hz', '8Hz', '14Hz']
    return [parse_quantity(v, 'frequency') for v in values]


def _clean(v):
    v = float(v)
    return v if math.isfinite(v) else None   # JSON has no inf: "no friction" -> null


def compute(args) -> list:
    from ..models import build_model, steady_state_properties, time_domain_properties
    spec = _spec(args)
    freqs = _frequencies(args)
    amps = [parse_quantity(v, 'length') for v in args.amplitude]
    for name, vals in (('frequency', freqs), ('amplitude', amps)):
        if any(not (v > 0) for v in vals):
            raise ValueError(f'{name} values must be > 0')
    rows = []
    if args.method == 'analytic':
        model = build_model(spec, dt=1e-3)
        for a in amps:
            for f in freqs:
                r = steady_state_properties(model, f, a)
                rows.append({k: _clean(r[k]) for k in KEYS})
    else:
        rate = parse_quantity(args.rate, 'frequency')
        if args.cycles < 3:
            raise ValueError('--cycles must be >= 3 (2 are analysed after at least one settling cycle)')
        model = build_model(spec, dt=1.0 / rate, scheme=args.scheme)
        for a in amps:
            for f in freqs:
                if f > 0.25 * rate:
                    raise ValueError(f'frequency {f:g} Hz needs a higher --rate than {rate:g} Hz (>= 4 samples/cycle)')
                r = time_domain_properties(model, f, a, cycles=args.cycles)
                rows.append({k: _clean(r[k]) for k in KEYS})
    return rows


def _table(rows) -> str:
    head = (f'{"f [Hz]":>9} {"x0 [mm]":>8} {"K_dyn [N/m]":>12} {"delta [deg]":>11} {"D [-]":>7} '
            f'{"C_eq [N s/m]":>13} {"E [J]":>10} {"R_K":>7} {"R_E":>7}')
    lines = [head, '-' * len(head)]
    for r in rows:
        rk = f'{r["r_k"]:7.3f}' if r['r_k'] is not None else f'{"-":>7}'
        re_ = f'{r["r_e"]:7.3f}' if r['r_e'] is not None else f'{"-":>7}'
        lines.append(f'{r["frequency"]:9.4g} {r["amplitude"] * 1e3:8.4g} {r["k_dyn"]:12.5e} '
                     f'{math.degrees(r["loss_angle"]):11.3f} {r["damping"]:7.4f} {r["c_eq"]:13.5e} '
                     f'{r["energy"]:10.4e} {rk} {re_}')
    return '\n'.join(lines)


def run(args) -> int:
    if args.list:
        from ..models import list_parameter_sets
        print('\n'.join(list_parameter_sets()))
        return 0
    rows = compute(args)
    print(json.dumps(rows, indent=1) if args.json else _table(rows))
    return 0
