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

"""Fitted parameter tables as YAML, in the format of the shipped sets (rubber_rig/models/data/*.yaml).

    sets:                        # loadable sets, exactly as the shipped file
      fit_20C: {model: fractional_zener_berg, temperature: 20.0, source: "...", values: {k0: ..., ...}}
    temperature_series: [fit_20C, ...]   # the sets identified per temperature, like seed 000 Table 1
    fit:                         # extra section (ignored by the set loader): quality and uncertainty
      fit_20C: {temperature, method, recordings, objective, relative_sigma, max_error, ...}

A file written here can be copied into rubber_rig/models/data/ and its sets loaded by name with
`rubber_rig.models.load_parameter_set`; `load_fit_file` reads it back directly. Files written before the
physics names (``model: seed000``, temperatures in a ``table1`` list) still load.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

import yaml

from rubber_rig.models import canonical_model, read_parameter_file, sets_with_aliases

from .identify import PARAM_NAMES


def set_name(temperature, prefix='fit'):
    if temperature is None:
        return prefix
    t = float(temperature)
    tag = f'{abs(t):g}'.replace('.', 'p')
    return f'{prefix}_{"m" if t < 0 else ""}{tag}C'


def table_dict(fits, prefix='fit', source=None) -> dict:
    src = source or f'rubber-rig fit, {_dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}'
    sets, extra = {}, {}
    for f in fits:
        name = set_name(f.temperature, prefix)
        values = {k: float(f'{f.params[k]:.6g}') for k in PARAM_NAMES}
        sets[name] = {'model': 'fractional_zener_berg',
                      **({} if f.temperature is None else {'temperature': float(f.temperature)}),
                      'source': src, 'values': values}
        ek, ec = f.max_errors('simulated')
        ak, ac = f.max_errors('analytic')
        extra[name] = {
            'temperature': f.temperature, 'method': f.method, 'recordings': list(f.runs),
            'blocks': len(f.blocks), 'objective_eq29': float(f'{f.eq29:.6g}'),
            'relative_sigma': {k: float(f'{v:.3g}') for k, v in f.uncertainty.get('relative_sigma', {}).items()},
            'max_error': {'k_dyn': float(f'{ek:.4g}'), 'c_eq': float(f'{ec:.4g}'),
                          'k_dyn_analytic': float(f'{ak:.4g}'), 'c_eq_analytic': float(f'{ac:.4g}')},
        }
    out = {'sets': sets}
    series = sorted((n for n, s in sets.items() if 'temperature' in s), key=lambda n: -sets[n]['temperature'])
    if series:
        out['temperature_series'] = series
    out['fit'] = extra
    return out


def write_fit_file(path, fits, prefix='fit', source=None) -> Path:
    path = Path(path)
    data = table_dict(fits, prefix, source)
    header = ('# Fractional Zener + Berg parameters identified by rubber-rig fit (SI: N/m, s, -, m, N).\n'
              '# Same layout as rubber_rig/models/data/swing_arm_joint.yaml; the "fit" section holds fit quality.\n')
    path.write_text(header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120))
    return path


def load_fit_file(path) -> dict:
    """{set name: {'model', 'values', 'temperature'}} of a parameter YAML (ours or a shipped one)."""
    data = read_parameter_file(path)
    sets = sets_with_aliases(data)
    temps = {}      # files written before each set stored its temperature: the table1 rows
    for row in data.get('table1') or []:
        vals = {k: row.get(k) for k in PARAM_NAMES}
        temps[tuple(sorted(vals.items()))] = row.get('temperature')
    out = {}
    for name, s in sets.items():
        if not isinstance(s, dict) or canonical_model(s.get('model')) != 'fractional_zener_berg':
            continue
        vals = s.get('values') or {}
        missing = [k for k in PARAM_NAMES if k not in vals]
        if missing:
            raise ValueError(f'{path}: set {name!r} lacks {missing}')
        vals = {k: float(vals[k]) for k in PARAM_NAMES}
        temp = s.get('temperature')
        if temp is None:
            temp = (data.get('fit') or {}).get(name, {}).get('temperature')
        if temp is None:
            temp = temps.get(tuple(sorted(vals.items())))
        out[name] = {'model': 'fractional_zener_berg', 'values': vals, 'temperature': temp}
    if not out:
        raise ValueError(f'{path}: no fractional_zener_berg parameter set')
    return out
