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

"""What a program's ``detectors:`` declare: the types, actions, thresholds and defaults, parsed and validated
(errors name the block and field). How they are judged on cycles: :mod:`.detectors`, whose docstring says what
each type and field means.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

from rubber_rig.units import to_si

TYPES = ('residual', 'stiffness_change', 'force_drift', 'tracking', 'cycle_count', 'elapsed_time', 'model_fit',
         'load_cell')
ACTIONS = ('record', 'warn', 'hold', 'end')
SEVERITY = {a: i for i, a in enumerate(ACTIONS)}     # when several trip together, the strongest action wins
TRIGGERS = ('cycle_count', 'elapsed_time')           # end-of-test triggers: judged on samples, not on cycles
DIAGNOSTICS = ('model_fit', 'load_cell')             # judge what the others see (excitation.diagnosis)
ON_MISMATCH = ('recalibrate', 'blind')               # model_fit: what becomes of the residual detectors
UNITS = {'k_dyn': 'N/m', 'c_eq': 'N s/m', 'loss_angle': 'rad'}
REFERENCES = ('program', 'stabilised', 'model')      # stiffness_change; the others use 'stabilised'
QUANTITIES = {'stiffness_change': ('k_dyn', 'c_eq', 'loss_angle'), 'force_drift': ('mean', 'amplitude')}
DEFAULT_ACTION = {'residual': 'hold', 'stiffness_change': 'end', 'force_drift': 'hold', 'tracking': 'hold',
                  'cycle_count': 'end', 'elapsed_time': 'end', 'model_fit': 'warn', 'load_cell': 'hold'}
# the threshold's dimension (rubber_rig.units) and its default (None: required)
THRESHOLD = {'residual': ('number', 4.0), 'stiffness_change': ('number', 0.2), 'force_drift': ('force', None),
             'tracking': ('number', 0.1), 'cycle_count': ('number', None), 'elapsed_time': ('time', None),
             'model_fit': ('number', 0.05), 'load_cell': ('number', 0.02)}
_DIMENSIONS = {'noise': 'force', 'floor': 'number', 'settle_cycles': 'number', 'reference_cycles': 'number',
               'consecutive': 'number', 'c_eq_threshold': 'number', 'confirm_cycles': 'number'}
# fields only one type uses (left out of the others' to_dict)
_OWN_FIELDS = {'c_eq_threshold': 'model_fit', 'on_mismatch': 'model_fit', 'confirm_cycles': 'load_cell'}
# model_fit/load_cell: medians and robust sigmas want more than 3 cycles (load_cell's sigma sets its step test)
DIAGNOSTIC_REFERENCE_CYCLES = {'model_fit': 8, 'load_cell': 16}
# The default detectors every program runs with unless it declares its own (excitation parameter
# `default_detectors`): thresholds from benchmarks/bench_detectors.py (README, "Detectors").
DEFAULTS = ({'type': 'residual'}, {'type': 'stiffness_change'}, {'type': 'force_drift', 'threshold': 0.1},
            {'type': 'tracking', 'action': 'warn'}, {'type': 'model_fit'}, {'type': 'load_cell'})


class DetectorError(ValueError):
    """A detector declaration is invalid; the message names where (program or block) and the field."""


@dataclass
class DetectorSpec:
    """One declared detector (SI units; see the module docstring)."""

    type: str
    name: str = ''
    action: str = ''
    threshold: float = math.nan
    threshold_units: str = ''        # 'N' for an absolute force_drift bound, '' for a fraction or count
    quantity: str = ''
    reference: str = 'stabilised'   # stiffness_change: 'program' by default (parse_detector)
    consecutive: int = 1
    settle_cycles: int = 3
    reference_cycles: int = 3
    noise: float = 0.0
    floor: float = 0.01
    c_eq_threshold: float = 0.15     # model_fit: tolerance of the C_eq ratio (threshold: of the K_dyn ratio)
    on_mismatch: str = 'recalibrate'  # model_fit: what becomes of the residual detectors (ON_MISMATCH)
    confirm_cycles: int = 8          # load_cell: at most this many cycles after a mean-force step to tell its cause
    block: int = -1                  # -1: the whole program

    def to_dict(self) -> dict:
        """As program YAML fields (SI), so a rewritten program keeps its detectors."""
        d = {f.name: getattr(self, f.name) for f in fields(self)
             if f.name not in ('threshold_units', 'block') and getattr(self, f.name) != ''
             and _OWN_FIELDS.get(f.name, self.type) == self.type}
        if self.threshold_units == 'N':
            d['threshold'] = f'{self.threshold:g} N'
        return d


def parse_detectors(raw, where: str, block: int = -1) -> list[DetectorSpec]:
    """DetectorSpecs of a ``detectors:`` list; ``where`` ('program' or "block 3 'name'") prefixes errors."""
    if raw is None:
        return []
    if not isinstance(raw, list):
        raise DetectorError(f"{where}: field 'detectors': expected a list of detectors like [{{type: residual}}]")
    out = [parse_detector(d, f'{where}: detectors[{i}]', block) for i, d in enumerate(raw)]
    names = [d.name for d in out]
    for n in names:
        if names.count(n) > 1:
            raise DetectorError(f"{where}: detectors: two detectors named {n!r} (give each a 'name')")
    return out


def parse_detector(raw, where: str, block: int = -1) -> DetectorSpec:
    if not isinstance(raw, dict):
        raise DetectorError(f'{where}: expected a mapping like {{type: stiffness_change, threshold: 0.2}}')
    kind = raw.get('type')
    if kind not in TYPES:
        raise DetectorError(f"{where}: field 'type': {kind!r} is not one of {', '.join(TYPES)}")
    known = {f.name for f in fields(DetectorSpec)} - {'threshold_units', 'block'}
    for key in raw:
        if key not in known:
            raise DetectorError(f"{where}: field '{key}': unknown (known: {', '.join(sorted(known))})")
    spec = DetectorSpec(type=kind, name=str(raw.get('name') or kind), block=block)
    spec.action = raw.get('action', DEFAULT_ACTION[kind])
    if spec.action not in ACTIONS:
        raise DetectorError(f"{where}: field 'action': {spec.action!r} is not one of {', '.join(ACTIONS)}")
    dim, default = THRESHOLD[kind]
    value = raw.get('threshold', default)
    if value is None:
        raise DetectorError(f"{where}: field 'threshold': required for a {kind} detector")
    if kind == 'force_drift' and isinstance(value, (int, float)) and not isinstance(value, bool):
        dim = 'number'                          # a plain number: a fraction of the force amplitude
    spec.threshold_units = 'N' if dim == 'force' else ''
    spec.threshold = _number(value, dim, where, 'threshold')
    if not spec.threshold > 0:
        raise DetectorError(f"{where}: field 'threshold': must be > 0, got {value!r}")
    for key, dim in _DIMENSIONS.items():
        if key in raw:
            setattr(spec, key, _number(raw[key], dim, where, key))
    if kind in DIAGNOSTICS and 'reference_cycles' not in raw:
        spec.reference_cycles = DIAGNOSTIC_REFERENCE_CYCLES[kind]
    for key in ('consecutive', 'settle_cycles', 'reference_cycles', 'confirm_cycles'):
        v = getattr(spec, key)
        if v != int(v) or v < (1 if key != 'settle_cycles' else 0) or v > 10000:
            raise DetectorError(f"{where}: field '{key}': a whole number within "
                                f"{1 if key != 'settle_cycles' else 0}..10000, got {raw[key]!r}")
        setattr(spec, key, int(v))
    if spec.noise < 0 or not 0 <= spec.floor < 1:
        raise DetectorError(f"{where}: field 'noise'/'floor': noise >= 0 N and floor within 0..1")
    for key, owner in _OWN_FIELDS.items():
        if key in raw and kind != owner:
            raise DetectorError(f"{where}: field '{key}': only a {owner} detector uses it")
    spec.on_mismatch = str(raw.get('on_mismatch', spec.on_mismatch))
    if spec.on_mismatch not in ON_MISMATCH:
        raise DetectorError(f"{where}: field 'on_mismatch': {spec.on_mismatch!r} is not one of "
                            f"{', '.join(ON_MISMATCH)}")
    if not spec.c_eq_threshold > 0:
        raise DetectorError(f"{where}: field 'c_eq_threshold': must be > 0, got {raw.get('c_eq_threshold')!r}")
    if kind in DIAGNOSTICS and block >= 0:
        raise DetectorError(f"{where}: a {kind} detector judges the whole program: declare it under the program's "
                            "'detectors', not a block's")
    quantities = QUANTITIES.get(kind)
    spec.quantity = str(raw.get('quantity', quantities[0] if quantities else ''))
    if quantities and spec.quantity not in quantities:
        raise DetectorError(f"{where}: field 'quantity': {spec.quantity!r} is not one of {', '.join(quantities)}")
    if not quantities and 'quantity' in raw:
        raise DetectorError(f"{where}: field 'quantity': not used by a {kind} detector")
    stiffness = kind == 'stiffness_change'
    spec.reference = str(raw.get('reference', 'program' if stiffness else 'stabilised'))
    if spec.reference not in REFERENCES or (spec.reference != 'stabilised' and not stiffness):
        allowed = ', '.join(repr(r) for r in REFERENCES) if stiffness else "'stabilised'"
        raise DetectorError(f"{where}: field 'reference': {allowed}, got {spec.reference!r}")
    return spec


def _number(value, dim, where, key) -> float:
    try:
        v = to_si(value, dim)
    except ValueError as exc:
        raise DetectorError(f"{where}: field '{key}': {exc}") from None
    if not math.isfinite(v):
        raise DetectorError(f"{where}: field '{key}': must be finite, got {value!r}")
    return v


def with_defaults(own: list[DetectorSpec], defaults: list[DetectorSpec]) -> list[DetectorSpec]:
    """A program's own detectors plus the defaults of the types (and names) it does not declare: a program with
    its own stiffness_change criterion does not also run the default one.
    """
    taken = {d.type for d in own} | {d.name for d in own}
    return list(own) + [d for d in defaults if d.type not in taken and d.name not in taken]
