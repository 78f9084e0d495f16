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

"""Seed-000 parameter tables as YAML, in the format of the shipped sets (rubber_rig/models/data/*.yaml).

    sets:
      fit_20C: {model: fractional_zener_berg, temperature: 20.0, source: "...", values: {k0: ..., ...}}
    temperature_series: [fit_20C, ...]

`rubber-rig fit` wrote these before it wrote model files; `load_fit_file` still reads them (and the
shipped sets) for `rubber-rig report --fit`. Files written before the physics names (``model: seed000``,
temperatures in a ``table1`` list) still load.
"""
from __future__ import annotations

import dataclasses

from rubber_rig.models import ZenerBergParams, canonical_model, read_parameter_file, sets_with_aliases

PARAM_NAMES = tuple(f.name for f in dataclasses.fields(ZenerBergParams))   # k0, k_inf, tau, alpha, x2, f_fmax


def set_name(temperature, prefix='fit'):
    if temperature is None:
        return prefix
    t = float(temperature)
    tag = f'{abs(t):g}'.replace('.', 'p')
    return f'{prefix}_{"m" if t < 0 else ""}{tag}C'


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
