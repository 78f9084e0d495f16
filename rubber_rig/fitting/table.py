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

"""Fit a model to a table of measured K_dyn and C_eq: what papers and vendor reports publish.

CSV with a header row; a column's unit goes in brackets after its name (no brackets: SI):

    frequency [Hz], amplitude [mm], preload [mm], temperature [degC], k_dyn [kN/mm], c_eq [kNs/m]
    2, 0.3, -0.9, 23, 2.95, 21.4

Required: frequency, amplitude, k_dyn, c_eq. Optional: preload (the mean displacement, alias mean),
temperature (rows are fitted per temperature), k_dyn_sigma and c_eq_sigma (1-sigma measurement
uncertainty, same units as their value; without them the scatter of the fit sets the uncertainty).
Only the harmonic objective applies (seed 000 Eq. 29 with the model's exact first harmonics).

A table carries no calibration: the load cell's gain and delay uncertainties of the test that measured it are
given to the fit (``gain_u``, ``delay_u``: ``rubber-rig fit --load-cell-gain-u/--load-cell-delay-u``) and enter
each parameter's budget (budget.add_budget) as for a recording: a gain error scales K_dyn and C_eq alike; a
delay d shifts each row's phase by w d, so C_eq by K_dyn cos(phi) d. Without them the fit warns
(calibration_undeclared).
"""
from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import numpy as np

from rubber_rig.models.modelfile import resolve_model
from rubber_rig.units import to_si

from .blocks import BlockResult
from .budget import add_budget, linearised_shift
from .extrapolation import mark_extrapolations
from .group_fit import block_quality, harmonic_uncertainty
from .misfit import misfit_test
from .modelfit import ModelFit
from .search import BlockTargets, coordinates, fit_harmonic_model, harmonic_residuals
from .verdict import notes, verdict

COLUMNS = {'frequency': 'frequency', 'amplitude': 'length', 'preload': 'length', 'mean': 'length',
           'temperature': 'temperature', 'k_dyn': 'stiffness', 'c_eq': 'damping', 'k_dyn_sigma': 'stiffness',
           'c_eq_sigma': 'damping'}
REQUIRED = ('frequency', 'amplitude', 'k_dyn', 'c_eq')
_HEADER = re.compile(r'^\s*([A-Za-z_]+)\s*(?:\[(.*)\])?\s*$')


def read_table(path) -> list:
    """Rows of a K_dyn / C_eq table as dicts in SI (see the module docstring); errors name file, row, column."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f'no such table: {path}')
    with open(path, newline='', encoding='utf-8') as fh:
        reader = csv.reader(fh)
        try:
            header = next(reader)
        except StopIteration:
            raise ValueError(f'{path}: empty file; expected a header row like '
                             '"frequency [Hz], amplitude [mm], k_dyn [kN/mm], c_eq [kNs/m]"') from None
        cols = []
        for h in header:
            m = _HEADER.match(h)
            name = m.group(1).lower() if m else h.strip()
            if name not in COLUMNS:
                raise ValueError(f'{path}: unknown column {h.strip()!r}; known: {", ".join(COLUMNS)}')
            cols.append((name, (m.group(2) or '').strip()))
        missing = [c for c in REQUIRED if c not in [n for n, _ in cols]]
        if missing:
            raise ValueError(f'{path}: missing column(s) {", ".join(missing)}')
        rows = []
        for line, raw in enumerate(reader, start=2):
            if not raw or all(not c.strip() for c in raw):
                continue
            if len(raw) != len(cols):
                raise ValueError(f'{path}:{line}: {len(raw)} values for {len(cols)} columns')
            row = {}
            for (name, unit), text in zip(cols, raw, strict=True):
                try:
                    row[name] = to_si(f'{text.strip()} {unit}'.strip(), COLUMNS[name])
                except ValueError as exc:
                    raise ValueError(f'{path}:{line}: column {name}: {exc}') from None
            for name in ('frequency', 'amplitude', 'k_dyn', 'c_eq'):
                if not row[name] > 0:
                    raise ValueError(f'{path}:{line}: {name} must be > 0, got {row[name]:g} (SI)')
            row['mean'] = row.pop('preload', row.get('mean', 0.0))
            rows.append(row)
    if not rows:
        raise ValueError(f'{path}: no data rows')
    return rows


def _blocks(rows, name):
    out = []
    for i, r in enumerate(rows):
        w = 2 * math.pi * r['frequency']
        energy = math.pi * w * r['c_eq'] * r['amplitude'] ** 2
        loss = math.asin(min(1.0, w * r['c_eq'] / r['k_dyn']))
        out.append(BlockResult(index=i, start=0, stop=0, cycles=0, skipped_cycles=0, frequency=r['frequency'],
                               amplitude=r['amplitude'], mean=r['mean'], k_dyn=r['k_dyn'], loss_angle=loss,
                               damping=math.sin(loss), energy=energy, c_eq=r['c_eq'], recording=name))
    return out


def _delay_shift(spec, coords, z, ls, t, w_k, w_c) -> dict:
    """Each parameter's change per second of load-cell delay behind the table's rows (budget.linearised_shift)."""
    h = 1e-6
    base = t.delay

    def residuals(d):
        t.delay = base + d
        try:
            return harmonic_residuals(z, spec, coords, t, w_k, w_c)
        finally:
            t.delay = base
    # the model seen through a load cell late by d looks like data measured through one early by d
    jd = -(residuals(h) - residuals(-h)) / (2 * h)
    shift, _ = linearised_shift(coords, z, ls.jac, jd)
    return shift


def fit_table(path, model='zener_berg', w_k=100.0, w_c=1.0, seed=0, gain_u=None, delay_u=None,
              displacement_gain_u=None, temperature_u=None) -> tuple:
    """Fit ``model`` to the table at ``path``; one fit per temperature. Returns (fits, messages).

    gain_u: relative standard uncertainty of the load-cell gain the table was measured with; delay_u: standard
    uncertainty [s] of its delay; displacement_gain_u: relative standard uncertainty of the displacement
    transducer's gain (the amplitude column); temperature_u: standard uncertainty [K] of the temperature
    column; None: not declared (the fit warns, calibration_undeclared).
    """
    spec = resolve_model(model)
    rows = read_table(path)
    groups = {}
    for r in rows:
        t = r.get('temperature')
        groups.setdefault(None if t is None else round(t * 2) / 2, []).append(r)
    fits, messages = [], []
    for temp, group in sorted(groups.items(), key=lambda kv: (kv[0] is None, kv[0] or 0)):
        blocks = _blocks(group, Path(path).name)
        t = BlockTargets.from_blocks(blocks, {})
        if all('k_dyn_sigma' in r and 'c_eq_sigma' in r for r in group):
            t.rel_sigma_k = np.array([r['k_dyn_sigma'] / r['k_dyn'] for r in group])
            t.rel_sigma_c = np.array([r['c_eq_sigma'] / r['c_eq'] for r in group])
        else:
            t.rel_sigma_k = t.rel_sigma_c = np.zeros(len(group))
            messages.append(f'{path}: no k_dyn_sigma / c_eq_sigma columns: the uncertainty comes from the scatter '
                            'of the fit alone and chi2/dof is not measured against the measurement noise')
        if 2 * len(group) < len(spec.free()) + 1:
            messages.append(f'{temp} degC: {len(group)} rows cannot fit {len(spec.free())} parameters')
            continue
        coords = coordinates(spec, t, 1e-3)
        z, ls = fit_harmonic_model(spec, coords, t, w_k, w_c, seed=seed)
        unc, corr, chi2, dof = harmonic_uncertainty(coords, z, ls, t, w_k, w_c)
        add_budget(unc, dict(zip(coords.names, coords.kinds, strict=True)),
                   {n: spec.param_spec(n).scale for n in coords.names},
                   {'gain': 1.0, 'gain_u': gain_u, 'delay_u': delay_u, 'displacement_gain_u': displacement_gain_u},
                   delay_shift=_delay_shift(spec, coords, z, ls, t, w_k, w_c),
                   units={n: spec.param_spec(n).unit for n in coords.names})
        values = coords.values(z)
        fitted = spec.with_values(values)
        band = mark_extrapolations(fitted, dict(values), blocks, unc)
        fit = ModelFit(model=fitted, temperature=temp, runs=[Path(path).name], blocks=blocks, method='harmonic',
                       parameters={n: float(values[n]) for n in coords.names}, uncertainty=unc,
                       correlation=corr.tolist(), chi2=chi2, dof=dof, n_points=2 * len(group), noise={},
                       load_cell={'delay': 0.0, 'gain': 1.0, 'calibration_source': 'declared' if gain_u is not None
                                  and delay_u is not None else 'none', 'gain_u': gain_u, 'delay_u': delay_u,
                                  'displacement_gain_u': displacement_gain_u, 'temperature_u': temperature_u},
                       quality=block_quality(fitted, blocks, {}, {}, sigmas=(t.rel_sigma_k, t.rel_sigma_c)))
        fit.band = band
        if not np.all(t.rel_sigma_k > 0):
            fit.chi2, fit.dof = float('nan'), dof
        else:   # the stated sigmas are the noise model: declared, so no estimate's uncertainty enters the test
            fit.misfit = misfit_test(chi2, dof, 0.0)
        fit.warnings = verdict(fit, coords)
        fit.notes = notes(fit)
        fits.append(fit)
    if not fits:
        raise ValueError('nothing could be fitted: ' + '; '.join(messages))
    return fits, messages
