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

"""Model files: a specimen or a fitted model as YAML, elements in parallel, values with units.

    name: bushing_20C                      # optional
    temperature: 20 degC                   # optional, what the values are valid at
    elements:
      - {type: fractional_zener, k0: 12.29 kN/mm, k_inf: 14.01 kN/mm, tau: 0.043 s, alpha: 0.659}
      - {type: berg, x2: 1.41 mm, f_fmax: 4.57 kN, fixed: [x2]}
      - {type: polynomial_spring, k3: 6e11 N/m^3}

A value is a number (SI) or a string with a unit of its parameter's dimension (``rubber-rig models``
lists them); ``fixed`` names the parameters a fit keeps. ``rubber-rig fit`` writes the same layout in
SI with ``sigma`` (1 sigma) and ``interval_95`` beside the values of each element; reading ignores them.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from rubber_rig.units import to_si

from .catalogue import build_operating_point_spring, element_type
from .element_spec import RESULT_KEYS, ElementSpec, parse_element
from .params import ParameterValueError, load_parameter_set, parameter_set_info
from .yamlfile import read_yaml_file


@dataclass
class ModelSpec:
    """Elements in parallel (seed 000 Eq. 1), as a model file describes them."""

    elements: list
    name: str = ''
    meta: dict = field(default_factory=dict)

    # ---- parameters ------------------------------------------------------------------------------
    def labels(self) -> list:
        """Element labels: the type, numbered (type_1, type_2) when a type occurs more than once."""
        types = [e.type for e in self.elements]
        return [f'{t}_{types[:i + 1].count(t)}' if types.count(t) > 1 else t for i, t in enumerate(types)]

    def parameters(self) -> list:
        """(name, element index, parameter name) of every parameter, in file order. ``name`` is the bare
        parameter name when it is unique in the model, else ``label.param``.
        """
        raw = [(i, p) for i, e in enumerate(self.elements) if e.fittable for p in e.values]
        bare = [p for _, p in raw]
        labels = self.labels()
        return [(p if bare.count(p) == 1 else f'{labels[i]}.{p}', i, p) for i, p in raw]

    def free(self) -> list:
        """The parameters a fit adjusts: all but the fixed ones."""
        return [t for t in self.parameters() if t[2] not in self.elements[t[1]].fixed]

    def values(self) -> dict:
        return {n: self.elements[i].values[p] for n, i, p in self.parameters()}

    def param_spec(self, name):
        for n, i, p in self.parameters():
            if n == name:
                return element_type(self.elements[i].type).param(p)
        raise KeyError(name)

    def canonical_names(self, values: dict | None = None) -> dict:
        """{parameter name: the name it has once repeated elements of a type are in canonical order}.

        Two Maxwell branches (or Zener elements) fitted to data can come back in either order: the model is
        the same with their labels swapped. The canonical order is by relaxation time, shortest first
        (Maxwell c / k, Zener tau), so that branch 1 of a fit is branch 1 of the truth and of the next fit.
        Identity for a model without such repeats. ``values``: parameter values to order by (default: the
        spec's own).
        """
        values = self.values() if values is None else values
        params = self.parameters()
        name_of = {(i, p): n for n, i, p in params}

        def relaxation(i):
            e = self.elements[i]
            v = {p: float(values.get(name_of.get((i, p)), e.values[p])) for p in e.values if (i, p) in name_of}
            if 'tau' in v:
                return v['tau']
            if 'c' in v and 'k' in v and v['k'] > 0:
                return v['c'] / v['k']
            return None

        mapping = {n: n for n, _, _ in params}
        types = [e.type for e in self.elements]
        for t in set(types):
            idx = [i for i, ti in enumerate(types) if ti == t]
            taus = [relaxation(i) for i in idx]
            if len(idx) < 2 or any(x is None for x in taus) or any(
                    self.elements[i].fixed != self.elements[idx[0]].fixed for i in idx):
                continue
            order = [idx[k] for k in sorted(range(len(idx)), key=lambda k: taus[k])]
            for slot, src in zip(idx, order, strict=True):      # element src's values go to position slot
                for p in self.elements[src].values:
                    if (src, p) in name_of and (slot, p) in name_of:
                        mapping[name_of[(src, p)]] = name_of[(slot, p)]
        return mapping

    def with_values(self, values: dict) -> 'ModelSpec':
        """A copy with some parameters (by ``parameters()`` name) replaced."""
        out = copy.deepcopy(self)
        for n, i, p in out.parameters():
            if n in values:
                out.elements[i].values[p] = float(values[n])
        return out

    def validate(self) -> 'ModelSpec':
        for n, i, p in self.parameters():
            spec = element_type(self.elements[i].type).param(p)
            v = self.elements[i].values[p]
            if not math.isfinite(v):
                raise ParameterValueError(n, f'must be finite, got {v}')
            if not spec.signed and v <= 0:
                raise ParameterValueError(n, f'must be > 0 [{spec.unit}], got {v:g}')
            if spec.upper is not None and v > spec.upper:
                raise ParameterValueError(n, f'must be <= {spec.upper:g}, got {v:g}')
            if spec.lower is not None and v < spec.lower:
                raise ParameterValueError(n, f'must be >= {spec.lower:g} ({spec.doc}), got {v:g}')
            if spec.above and v < self.elements[i].values[spec.above]:
                raise ParameterValueError(n, f'({v:g} {spec.unit}) must be >= {spec.above} '
                                             f'({self.elements[i].values[spec.above]:g} {spec.unit})')
        return self

    # ---- physics ---------------------------------------------------------------------------------
    def build_elements(self, dt: float, reversal_threshold: float | None = None, scheme=None) -> list:
        """Streaming/batch element objects at sample period ``dt`` [s]. ``reversal_threshold`` [m] and the
        fractional operator ``scheme``, when given, apply to every element that has the option and sets none.
        """
        return [self.build_element(i, dt, reversal_threshold, scheme) for i in range(len(self.elements))]

    def build_element(self, index: int, dt: float, reversal_threshold: float | None = None, scheme=None):
        """The element object of ``elements[index]`` (as :meth:`build_elements` builds each)."""
        e = self.elements[index]
        if not e.fittable:
            return build_operating_point_spring(e.values, dt)
        t = element_type(e.type)
        opts = dict(e.options)
        for option, value in (('reversal_threshold', reversal_threshold), ('scheme', scheme)):
            if value is not None and option in t.options:
                opts.setdefault(option, value)
        return t.build(e.values, float(dt), opts)

    def first_harmonic(self, frequency, amplitude, mean=0.0, values: dict | None = None):
        """Complex first-harmonic stiffness [N/m] of the whole model under x = mean + A sin(2 pi f t)
        (see :mod:`.catalogue`). ``values``: {parameter name: array} overriding the model's values; arrays
        broadcast against ``frequency``/``amplitude`` (a fit passes a population as shape (S, 1)).
        """
        f, a, m = (np.asarray(v, float) for v in (frequency, amplitude, mean))
        total = 0j
        by_element = [dict(e.values) for e in self.elements]
        for name, i, p in self.parameters():
            if values is not None and name in values:
                by_element[i][p] = values[name]
        for e, v in zip(self.elements, by_element, strict=True):
            if not e.fittable:
                raise ValueError(f'{e.type} has operating-point coefficients: no single first harmonic')
            total = total + element_type(e.type).first_harmonic(v, f, a, m)
        return total

    # ---- files -----------------------------------------------------------------------------------
    def to_dict(self, results: dict | None = None) -> dict:
        """The model-file mapping in SI; ``results`` {parameter name: {sigma, interval_95}} goes beside
        the values of each element.
        """
        elements = []
        names = {(i, p): n for n, i, p in self.parameters()}
        for i, e in enumerate(self.elements):
            d = {'type': e.type}
            d.update({p: float(v) if not isinstance(v, (list, tuple)) else _plain(v) for p, v in e.values.items()})
            if e.fixed:
                d['fixed'] = sorted(e.fixed)
            d.update(_plain(e.options))
            if results:
                for key in RESULT_KEYS:
                    got = {p: results[names[(i, p)]][key] for p in e.values
                           if (i, p) in names and key in results.get(names[(i, p)], {})}
                    if got:
                        d[key] = _plain(got)
            elements.append(d)
        out = {'name': self.name} if self.name else {}
        out.update(_plain(self.meta))
        out['elements'] = elements
        return out

    def dump(self, path, results=None, header: str = '') -> Path:
        path = Path(path)
        text = yaml.safe_dump(self.to_dict(results), sort_keys=False, width=110, default_flow_style=None)
        path.write_text((header + '\n' if header else '') + text, encoding='utf-8')
        return path


def _plain(v):
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    return v


def parse_model(data, origin: str = 'model') -> ModelSpec:
    """A :class:`ModelSpec` from a model-file mapping; errors name ``origin`` and the entry."""
    if not isinstance(data, dict) or not isinstance(data.get('elements'), list) or not data['elements']:
        raise ValueError(f'{origin}: a model file needs "elements", a list of elements in parallel, e.g. '
                         '[{type: berg, x2: 1.4 mm, f_fmax: 4.6 kN}] (rubber-rig models lists the types)')
    elements = [parse_element(e, f'{origin}: elements[{i}]') for i, e in enumerate(data['elements'])]
    meta = {k: v for k, v in data.items() if k not in ('elements', 'name', 'model')}
    if 'temperature' in meta:
        meta['temperature'] = to_si(meta['temperature'], 'temperature')
    spec = ModelSpec(elements, str(data.get('name', '')), meta)
    try:
        return spec.validate()
    except ValueError as exc:
        raise ValueError(f'{origin}: {exc}') from None


def is_model_file(path) -> bool:
    """True when ``path`` is a YAML file with an ``elements`` list (not a parameter-set table)."""
    p = Path(str(path)).expanduser()
    if p.suffix not in ('.yaml', '.yml') or not p.is_file():
        return False
    try:
        data = read_yaml_file(p)
    except ValueError:   # unreadable, binary or not YAML: not a model file (whoever reads it says why)
        return False
    return isinstance(data, dict) and 'elements' in data


def load_model_file(path) -> ModelSpec:
    path = Path(str(path)).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f'no such model file: {path}')
    data = read_yaml_file(path)   # one-line ValueError: unreadable, binary, not YAML
    spec = parse_model(data, str(path))
    spec.name = spec.name or path.stem
    return spec


def spec_from_params(params, name: str = '') -> ModelSpec:
    """The model of a parameter dataclass (ZenerBergParams, TangentMaxwellBergParams, KelvinVoigtParams)."""
    v = params.as_dict()
    kind = type(params).__name__
    if kind == 'ZenerBergParams':
        els = [ElementSpec('fractional_zener', {k: v[k] for k in ('k0', 'k_inf', 'tau', 'alpha')}),
               ElementSpec('berg', {'x2': v['x2'], 'f_fmax': v['f_fmax']})]
    elif kind == 'TangentMaxwellBergParams':
        els = [ElementSpec('dzierzek', {'k_t': v['k_t'], 'd_t': v['d_t']}),
               ElementSpec('maxwell', {'k': v['k1'], 'c': v['c1']}),
               ElementSpec('maxwell', {'k': v['k2'], 'c': v['c2']}),
               ElementSpec('berg', {'x2': v['x2'], 'f_fmax': v['f_fmax']})]
    elif kind == 'KelvinVoigtParams':
        els = [ElementSpec('linear_spring', {'k': v['k']}), ElementSpec('dashpot', {'c': v['c']})]
    else:
        raise ValueError(f'cannot describe {kind} as a model file')
    return ModelSpec(els, name)


# Named models: starting structures for `rubber-rig fit --model NAME` (values are typical magnitudes; a fit
# starts from the data, not from them) and the specimens of the acceptance benchmark.
_SEED000 = [{'type': 'fractional_zener', 'k0': '12.29 kN/mm', 'k_inf': '14.01 kN/mm', 'tau': '0.043 s',
             'alpha': 0.659}, {'type': 'berg', 'x2': '1.41 mm', 'f_fmax': '4.57 kN'}]
NAMED_MODELS = {
    'zener_berg': ('seed 000: fractional Zener + Berg (6 parameters)', _SEED000),
    'zener_berg_cubic': ('seed 000 + cubic spring (7 parameters)',
                         _SEED000 + [{'type': 'polynomial_spring', 'k3': '6e11 N/m^3'}]),
    # the polynomial has no linear term: the two-order model's k1 is the static stiffness (two linear terms
    # in parallel are one parameter to any data)
    'seed003': ('seed 003 style: cubic spring + two-order fractional + Berg',
                [{'type': 'polynomial_spring', 'k3': '5e11 N/m^3'},
                 {'type': 'two_order_fractional', 'k1': '6 kN/mm', 'k2': '3 kN/mm', 'c1': 2.5e5, 'c2': 8.5e5,
                  'alpha': 0.3, 'beta': 0.6},
                 {'type': 'berg', 'x2': '0.3 mm', 'f_fmax': '0.8 kN'}]),
    'pad': ('seed 004 at one operating point: odd polynomial spring (k1, k3) + elliptic damping',
            [{'type': 'polynomial_spring', 'k1': '2.5 kN/mm', 'k3': '4.8 kN/mm^3'},
             {'type': 'elliptic_damping', 'b': '0.34 kN'}]),
    'tangent_maxwell_berg': ('seed 001 combined model: Dzierzek tangent spring + 2 Maxwell + Berg',
                             [{'type': 'dzierzek', 'k_t': '1 kN/mm', 'd_t': '10 mm'},
                              {'type': 'maxwell', 'k': '0.5 kN/mm', 'c': '2 kNs/m'},
                              {'type': 'maxwell', 'k': '0.3 kN/mm', 'c': '0.1 kNs/m'},
                              {'type': 'berg', 'x2': '0.5 mm', 'f_fmax': '0.3 kN'}]),
    'kelvin_voigt': ('linear spring + dashpot', [{'type': 'linear_spring', 'k': '13 kN/mm'},
                                                 {'type': 'dashpot', 'c': '20 kNs/m'}]),
    'maxwell_berg': ('linear spring + Maxwell + Berg',
                     [{'type': 'linear_spring', 'k': '12 kN/mm'}, {'type': 'maxwell', 'k': '2 kN/mm', 'c': '10 kNs/m'},
                      {'type': 'berg', 'x2': '1 mm', 'f_fmax': '4 kN'}]),
}


def named_model(name: str) -> ModelSpec:
    """A named model (``NAMED_MODELS``) or a shipped parameter set (e.g. swing_arm_joint_20C) as a ModelSpec."""
    if name in NAMED_MODELS:
        doc, elements = NAMED_MODELS[name]
        return parse_model({'name': name, 'description': doc, 'elements': elements}, name)
    try:
        params = load_parameter_set(name)
    except ValueError:
        raise ValueError(f'unknown model {name!r}: give a model file (.yaml with "elements") or one of '
                         f'{", ".join(NAMED_MODELS)}, or a parameter set (rubber-rig props --list)') from None
    info = parameter_set_info(name)
    spec = spec_from_params(params, name)
    if math.isfinite(info['temperature']):
        spec.meta['temperature'] = info['temperature']
    return spec


def resolve_model(source) -> ModelSpec:
    """A ModelSpec from a ModelSpec, a model file path, a named model, a parameter set or a mapping."""
    if isinstance(source, ModelSpec):
        return source
    if isinstance(source, dict):
        return parse_model(source)
    if is_model_file(source):
        return load_model_file(source)
    if str(source).endswith(('.yaml', '.yml')) and not Path(str(source)).expanduser().is_file():
        raise FileNotFoundError(f'no such model file: {source}')
    return named_model(str(source))
