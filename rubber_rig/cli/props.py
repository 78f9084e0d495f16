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

"""Steady-state properties of a rubber-element model: K_dyn, loss angle, D, C_eq, energy, R_K, R_E.

K_dyn (--kdyn): 'harmonic' (default) is the exact first harmonic, |F1 / X1| of force and displacement:
what a rig measures and what --method time computes. 'eq24' is seed 000's Eq. 19-24 as printed: Berg's
friction loop replaced by the ellipse of equal peak force (Eq. 19) and energy (Eq. 18, 21-22). The two
give the same energy, C_eq and R_E; K_dyn, the loss angle, D and R_K (Eq. 30) follow the definition. For
the four seed-000 temperature sets over 0.5-14 Hz at 0.5 and 1 mm, eq24's K_dyn is lower by 0.08-0.16 %
at 20 degC and by up to 1.03 % at -40 degC (0.5 Hz, 1 mm); its R_K is higher by up to 4.3 %.

--method time simulates each frequency at a whole number of samples per cycle, n = round(rate / f)
(the sample rate becomes f n, within f / 2 of --rate), so the last 2 cycles analysed are exactly 2n
samples and the first harmonic is the DFT bin of the excitation: within 0.01 % of the analytic
first harmonic at -40 degC, 1.3 Hz, 1 mm (the fractional scheme's own error). With --scheme paper the GL
step h becomes the whole multiple of that sample period nearest the paper's 1 ms.

Examples:
  rubber-rig props --parameter-set swing_arm_joint_20C --frequency 0.5Hz 4Hz 14Hz --amplitude 0.5mm 1mm
  rubber-rig props --temperature -10 --frequency-grid 0.5 14 8 --amplitude 1mm --json
  rubber-rig props --parameter-set swing_arm_joint_m40C --frequency 4 --amplitude 0.5mm --method time
  rubber-rig props --parameter-set swing_arm_joint_m40C --frequency 1.3 --kdyn eq24
Output in SI (N/m, N s/m, J; loss_angle in rad in JSON, in degrees in the table); JSON rows and the table
header name the K_dyn definition (kdyn_definition).
"""
from __future__ import annotations

import json
import math
import sys

import numpy as np

from rubber_rig.models import build_model, list_parameter_sets, steady_state_properties, time_domain_properties
from rubber_rig.models.simulate import whole_cycle_dt
from rubber_rig.units import to_si

KEYS = ('frequency', 'amplitude', 'k_dyn', 'loss_angle', 'damping', 'c_eq', 'energy', 'r_k', 'r_e')
KDYN_HELP = {'harmonic': 'exact first harmonic |F1/X1|', 'eq24': 'seed 000 Eq. 24 equal-peak ellipse'}
PAPER_GL_STEP = 1e-3                   # seed 000 Eq. 15: h = 1 ms (--scheme paper)

# Physical input ranges (SI); anything outside is a typo or a unit slip, refused with the range named.
AMPLITUDE_RANGE = (1e-9, 1.0)          # 1 nm .. 1 m displacement amplitude
FREQUENCY_RANGE = (1e-6, 1e6)          # 1 uHz .. 1 MHz
RATE_RANGE = (1.0, 1e6)                # --rate of --method time: 1 Hz .. 1 MHz
CYCLES_RANGE = (3, 10_000)             # --cycles of --method time
MAX_GRID_POINTS = 10_000               # --frequency-grid N
# Cost bound of --method time: samples simulated per (frequency, amplitude) point and in total. One
# sample costs about 90 bytes and 0.6 us (0.01 Hz x 30 cycles at 1 kHz = 3e6 samples: ~0.3 GB, ~2 s).
MAX_TIME_SAMPLES = 3_000_000
MAX_TIME_SAMPLES_TOTAL = 30_000_000


def add_arguments(parser):
    src = parser.add_mutually_exclusive_group()
    src.add_argument('--parameter-set', '-p', default=None,
                     help='named parameter set (default swing_arm_joint_20C); see --list')
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
    parser.add_argument('--kdyn', choices=('harmonic', 'eq24'), default='harmonic',
                        help='definition of K_dyn (and of the loss angle, D, R_K): harmonic (default) = the exact '
                             'first harmonic |F1/X1|, what a rig measures and what --method time computes; '
                             "eq24 = seed 000 Eq. 19-24, Berg's loop as the ellipse of equal peak force and energy "
                             '(--method analytic only). Energy, C_eq and R_E are the same in both. For the seed-000 '
                             'sets over 0.5-14 Hz, 0.5 and 1 mm eq24 is lower by up to 1.03 %% (-40 degC, 0.5 Hz, '
                             '1 mm; 0.16 %% at 20 degC)')
    parser.add_argument('--rate', default='1kHz',
                        help='nominal sample rate of --method time (default 1kHz); each frequency f runs at '
                             'f round(rate/f), a whole number of samples per cycle')
    parser.add_argument('--scheme', default='default', choices=('default', 'paper', 'gl'),
                        help='fractional scheme of --method time (default: sum of exponentials)')
    parser.add_argument('--cycles', type=int, default=30, help='cycles simulated by --method time (last 2 analysed)')
    parser.add_argument('--json', action='store_true', help='print a JSON list of objects instead of a table')


def _spec(args):
    if args.temperature is not None:
        return {'model': 'fractional_zener_berg', 'temperature': to_si(args.temperature, 'temperature')}
    return {'parameter_set': args.parameter_set or 'swing_arm_joint_20C'}


def _frequencies(args):
    if args.frequency_grid is not None:
        lo, hi = (to_si(v, 'frequency') for v in args.frequency_grid[:2])
        try:
            n = int(args.frequency_grid[2])
        except ValueError:
            raise ValueError(f'--frequency-grid N must be a whole number, not {args.frequency_grid[2]!r}') from None
        if not 1 <= n <= MAX_GRID_POINTS:
            raise ValueError(f'--frequency-grid N = {n} is outside the allowed range 1 .. {MAX_GRID_POINTS}')
        for v, text in zip((lo, hi), args.frequency_grid[:2], strict=False):
            _check_range('--frequency-grid', v, FREQUENCY_RANGE, 'Hz', text)
        return list(np.geomspace(lo, hi, n))
    values = args.frequency or ['0.5Hz', '1Hz', '2Hz', '4Hz', '8Hz', '14Hz']
    freqs = [to_si(v, 'frequency') for v in values]
    for v, text in zip(freqs, values, strict=False):
        _check_range('--frequency', v, FREQUENCY_RANGE, 'Hz', text)
    return freqs


def _check_range(option, value, allowed, unit, text=None):
    lo, hi = allowed
    if not lo <= value <= hi:
        given = f'{value:g} {unit}'
        if text is not None and str(text) != f'{value:g}':
            given = f'{text} (= {given})'
        raise ValueError(f'{option} {given} is outside the allowed range {lo:g} .. {hi:g} {unit}')


def _check_time_cost(freqs, n_amps, rate, cycles):
    """Refuse --method time runs whose simulated length is unbounded in memory or time."""
    for f in freqs:
        if f > 0.25 * rate:
            raise ValueError(f'--frequency {f:g} Hz needs a higher --rate than {rate:g} Hz (>= 4 samples/cycle)')
    f_min = cycles * rate / MAX_TIME_SAMPLES
    slow = min(freqs)
    if slow < f_min:
        raise ValueError(f'--frequency {slow:g} Hz with --method time needs {cycles * rate / slow:.3g} samples '
                         f'({cycles} cycles at {rate:g} Hz); allowed: --frequency >= {f_min:.3g} Hz '
                         f'(at most {MAX_TIME_SAMPLES} samples per point), a lower --rate or fewer --cycles, '
                         f'or --method analytic')
    total = n_amps * sum(cycles * rate / f for f in freqs)
    if total > MAX_TIME_SAMPLES_TOTAL:
        raise ValueError(f'--method time over {len(freqs)} frequencies x {n_amps} amplitudes needs {total:.3g} '
                         f'samples; allowed: at most {MAX_TIME_SAMPLES_TOTAL} in total (fewer points, '
                         f'or --method analytic)')


def _clean(v):
    v = float(v)
    return v if math.isfinite(v) else None   # JSON has no inf: "no friction" -> null


def _time_scheme(scheme, dt):
    """--scheme at sample period dt: the paper's GL step h = 1 ms rounded to a whole multiple of dt."""
    if scheme == 'paper':
        return {'name': 'paper', 'h': dt * max(1, round(PAPER_GL_STEP / dt))}
    return scheme


def _row(r, kdyn):
    return {**{k: _clean(r[k]) for k in KEYS}, 'kdyn_definition': kdyn}


def compute(args) -> list:
    kdyn = getattr(args, 'kdyn', 'harmonic')
    spec = _spec(args)
    freqs = _frequencies(args)
    amps = [to_si(v, 'length') for v in args.amplitude]
    for a, text in zip(amps, args.amplitude, strict=False):
        _check_range('--amplitude', a, AMPLITUDE_RANGE, 'm', text)
    rows = []
    if args.method == 'analytic':
        model = build_model(spec, dt=1e-3)
        for a in amps:
            for f in freqs:
                rows.append(_row(steady_state_properties(model, f, a, kdyn=kdyn), kdyn))
    else:
        if kdyn != 'harmonic':
            raise ValueError('--kdyn eq24 is a closed form (seed 000 Eq. 24): use it with --method analytic; '
                             '--method time measures the exact first harmonic (--kdyn harmonic)')
        rate = to_si(args.rate, 'frequency')
        _check_range('--rate', rate, RATE_RANGE, 'Hz', args.rate)
        if not CYCLES_RANGE[0] <= args.cycles <= CYCLES_RANGE[1]:
            raise ValueError(f'--cycles {args.cycles} is outside the allowed range {CYCLES_RANGE[0]} .. '
                             f'{CYCLES_RANGE[1]} (2 are analysed after at least one settling cycle)')
        _check_time_cost(freqs, len(amps), rate, args.cycles)
        models = {}
        for a in amps:
            for f in freqs:
                if f not in models:   # a whole number of samples per cycle: the analysed window is exact
                    dt = whole_cycle_dt(f, rate)
                    models[f] = build_model(spec, dt=dt, scheme=_time_scheme(args.scheme, dt))
                rows.append(_row(time_domain_properties(models[f], f, a, cycles=args.cycles), 'harmonic'))
    return rows


def _table(rows) -> str:
    head = (f'{"f [Hz]":>9} {"x0 [mm]":>8} {"K_dyn [N/m]":>12} {"delta [deg]":>11} {"D [-]":>7} '
            f'{"C_eq [N s/m]":>13} {"E [J]":>10} {"R_K":>7} {"R_E":>7}')
    lines = [head, '-' * len(head)]
    definitions = sorted({r['kdyn_definition'] for r in rows})
    if definitions:   # on the header line, so that rows stay lines[2:]
        lines[0] += '   K_dyn: ' + ', '.join(f'{d} ({KDYN_HELP[d]})' for d in definitions)

    def cell(value, fmt, width, scale=1.0):   # None: not finite (JSON null), shown as '-'
        return f'{"-":>{width}}' if value is None else f'{value * scale:{width}{fmt}}'

    for r in rows:
        delta = None if r['loss_angle'] is None else math.degrees(r['loss_angle'])
        lines.append(' '.join([cell(r['frequency'], '.4g', 9), cell(r['amplitude'], '.4g', 8, 1e3),
                               cell(r['k_dyn'], '.5e', 12), cell(delta, '.3f', 11), cell(r['damping'], '.4f', 7),
                               cell(r['c_eq'], '.5e', 13), cell(r['energy'], '.4e', 10), cell(r['r_k'], '.3f', 7),
                               cell(r['r_e'], '.3f', 7)]))
    return '\n'.join(lines)


def _not_finite_note(rows):
    """One stderr line naming the points whose closed forms or runs gave no finite K_dyn/loss angle."""
    bad = [r for r in rows if r['k_dyn'] is None or r['loss_angle'] is None]
    if not bad:
        return None
    where = ', '.join(f'{r["frequency"]:g} Hz x {r["amplitude"] * 1e3:g} mm' for r in bad[:5])
    more = f' and {len(bad) - 5} more' if len(bad) > 5 else ''
    if any(r['kdyn_definition'] == 'eq24' for r in bad):
        why = ("seed 000 Eq. 21 has no ellipse once Berg's loop is fuller than one (D_f > 1, large amplitudes); "
               '--kdyn harmonic is defined at any amplitude')
    else:
        why = ('amplitude beyond the numeric range of the closed forms for this parameter set; try a smaller '
               'amplitude or --method time')
    return f'rubber-rig props: warning: no finite K_dyn/loss angle at {where}{more} ({why})'


def run(args) -> int:
    if args.list:
        print('\n'.join(list_parameter_sets()))
        return 0
    rows = compute(args)
    print(json.dumps(rows, indent=1) if args.json else _table(rows))
    note = _not_finite_note(rows)
    if note:
        print(note, file=sys.stderr)
    return 0
