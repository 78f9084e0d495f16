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

"""Parallel composition of elements (seed 000 Eq. 1: F = sum of branch forces) and ``build_model``."""
from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np

from .friction import check_reversal_threshold
from .modelfile import ModelSpec, is_model_file, load_model_file, parse_model, spec_from_params
from .params import (
    PARAM_CLASSES,
    KelvinVoigtParams,
    TangentMaxwellBergParams,
    ZenerBergParams,
    canonical_model,
    load_parameter_set,
    model_class,
    parameters_at_temperature,
)

_BLOCK = 32768


class ParallelModel:
    """Elements in parallel at sample period ``dt`` [s]; the total force is the sum of the branch forces.

    ``branch_names`` (tuple of str) and ``branch_kinds`` ('elastic' | 'viscous' | 'friction') follow
    the element order. ``step(x)`` -> total force [N] (branch forces in ``last_branches``);
    ``run(x, return_branches=False)`` continues from the current state and leaves it as the same
    number of ``step`` calls would (to round-off).
    """

    def __init__(self, elements, dt: float, name: str = 'parallel', params=None):
        if not elements:
            raise ValueError('a model needs at least one element')
        self.elements = list(elements)
        self.dt = float(dt)
        self.name, self.params = name, params
        names, kinds = [], []
        for e in self.elements:
            names += list(e.branch_names)
            kinds += list(e.kinds)
        # unique branch names: repeated kinds get a _1, _2 ... suffix
        self.branch_names = tuple(
            f'{n}_{names[:i + 1].count(n)}' if names.count(n) > 1 else n for i, n in enumerate(names))
        self.branch_kinds = tuple(kinds)
        self._last = [0.0] * len(names)
        self._steps = [e.step for e in self.elements]

    @property
    def last_branches(self) -> np.ndarray:
        """Branch forces [N] of the last sample (``step`` or the end of ``run``), in ``branch_names`` order."""
        return np.array(self._last, dtype=float)

    def step(self, x: float) -> float:
        x = float(x)
        last = []
        for step in self._steps:      # plain floats: numpy calls cost more than the arithmetic here
            last.extend(step(x))
        self._last = last
        return sum(last)

    def run(self, x, return_branches: bool = False):
        """Total force [N], shape (n,); with ``return_branches`` also branch forces, shape (n_branch, n)."""
        x = np.ascontiguousarray(x, dtype=float)
        if x.ndim != 1:
            raise ValueError(f'x must be a 1-D array of displacements [m], got shape {x.shape}')
        n = x.size
        nb = len(self._last)
        total = np.empty(n)
        # blocks small enough for the per-mode temporaries to stay in cache (about 2x faster on
        # long records); every element continues its own state across blocks. Without
        # return_branches only a block-sized scratch array is needed.
        branches = np.empty((nb, n)) if return_branches else np.empty((nb, min(n, _BLOCK)))
        for s in range(0, n, _BLOCK):
            xb = x[s:s + _BLOCK]
            cols = slice(s, s + xb.size) if return_branches else slice(0, xb.size)
            i = 0
            for e in self.elements:
                r = e.run(xb)
                branches[i:i + r.shape[0], cols] = r
                i += r.shape[0]
            branches[:, cols].sum(axis=0, out=total[s:s + xb.size])
            if s + xb.size == n:
                self._last = branches[:, cols][:, -1].tolist()
        return (total, branches) if return_branches else total

    def reset(self, x0: float = 0.0):
        """Back to the relaxed (virgin) state at displacement x0 [m]."""
        for e in self.elements:
            e.reset(float(x0))
        self._last = [0.0] * len(self.branch_names)

    def get_state(self):
        return copy.deepcopy(([e.get_state() for e in self.elements], list(self._last)))

    def set_state(self, state):
        states, last = copy.deepcopy(state)
        for e, s in zip(self.elements, states, strict=False):
            e.set_state(s)
        self._last = [float(v) for v in last]

    def complex_stiffness(self, frequency, amplitude):
        """Exact continuous (equivalent) complex stiffness per branch [N/m], shape (n_branch, ...)."""
        return np.concatenate([e.complex_stiffness(frequency, amplitude) for e in self.elements])


def _parallel(params, dt, scheme='default', friction_reversal_threshold: float = 0.0) -> ParallelModel:
    """The model of a parameter dataclass, built like any model file: through its :class:`ModelSpec`."""
    params.validate()
    name = next(n for n, cls in PARAM_CLASSES.items() if isinstance(params, cls))
    return ParallelModel(spec_from_params(params).build_elements(dt, friction_reversal_threshold, scheme), dt, name,
                         params)


def zener_berg_model(params: ZenerBergParams, dt: float, scheme='default',
                     friction_reversal_threshold: float = 0.0) -> ParallelModel:
    """Seed 000's nonlinear rubber spring: fractional Zener + Berg; branches ('elastic', 'viscous', 'friction').

    ``friction_reversal_threshold`` [m]: Berg's reversal deadband (see :mod:`.friction`), 0 = the paper's rule.
    """
    return _parallel(params, dt, scheme, friction_reversal_threshold)


def tangent_maxwell_berg_model(params: TangentMaxwellBergParams, dt: float,
                               friction_reversal_threshold: float = 0.0) -> ParallelModel:
    """Seed 001's combined model: tangent spring + 2 Maxwell + Berg.

    Branches ('elastic', 'viscous_1', 'viscous_2', 'friction').
    """
    return _parallel(params, dt, friction_reversal_threshold=friction_reversal_threshold)


def kelvin_voigt_model(params: KelvinVoigtParams, dt: float) -> ParallelModel:
    return _parallel(params, dt)


def resolve_params(spec):
    """Parameters of a spec: a params dataclass, a parameter-set name or a dict spec (see ``build_model``)."""
    if isinstance(spec, (ZenerBergParams, TangentMaxwellBergParams, KelvinVoigtParams)):
        return spec
    if isinstance(spec, str):
        return load_parameter_set(spec)
    if not isinstance(spec, dict):
        raise ValueError(f'model spec must be parameters, a parameter-set name or a dict, got {type(spec).__name__}')
    model = canonical_model(spec.get('model', 'fractional_zener_berg'))
    sources = [k for k in ('parameter_set', 'temperature', 'values') if k in spec]
    if len(sources) != 1:
        raise ValueError(f"model spec needs exactly one of 'parameter_set', 'temperature', 'values', got {sources}")
    if 'parameter_set' in spec:
        p = load_parameter_set(spec['parameter_set'])
    elif 'temperature' in spec:
        if model != 'fractional_zener_berg':
            raise ValueError(f"'temperature' is only available for model 'fractional_zener_berg', not {model!r}")
        p = parameters_at_temperature(spec['temperature'])
    else:
        p = model_class(model).from_dict(spec['values'])
    return p


def _check_threshold(value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    return check_reversal_threshold(v, value, 'friction_reversal_threshold')


def _model_spec(source):
    """The ModelSpec of a model-file source (ModelSpec, mapping with ``elements`` or ``model_file``, model-file
    path), else None (a parameter-set source).
    """
    if isinstance(source, ModelSpec):
        return source
    if isinstance(source, dict):
        if 'model_file' in source:
            extra = set(source) - {'model_file', 'scheme', 'friction_reversal_threshold', 'temperature'}
            if extra:
                raise ValueError(f'a specimen given by model_file takes no {", ".join(sorted(extra))}: '
                                 'put them in the model file')
            return load_model_file(source['model_file'])
        if 'elements' in source:
            return parse_model({k: v for k, v in source.items() if k not in ('scheme', 'friction_reversal_threshold')},
                               'model spec')
        if isinstance(source.get('parameter_set'), (str, Path)) and is_model_file(source['parameter_set']):
            return load_model_file(source['parameter_set'])   # as element_model's parameter_set: it brings its model
        return None
    if isinstance(source, (str, Path)) and is_model_file(source):
        return load_model_file(source)
    return None


def build_model(params_or_spec, dt: float, scheme='default', friction_reversal_threshold: float = 0.0) -> ParallelModel:
    """Model object at sample period ``dt`` [s].

    ``params_or_spec``: a :class:`ZenerBergParams` / :class:`TangentMaxwellBergParams` /
    :class:`KelvinVoigtParams`; a parameter-set name; or a dict
    ``{"model": "fractional_zener_berg", "parameter_set": "swing_arm_joint_20C"}``,
    ``{"model": "fractional_zener_berg", "temperature": -10}``, ``{"model": "fractional_zener_berg", "values": {...}}``,
    ``{"elements": [{"type": "berg", "f_fmax": "4.57 kN", "x2": "1.41 mm"}, ...]}`` (a model file's mapping,
    see :mod:`.modelfile`), ``{"model_file": "specimen.yaml"}`` (or a model file as ``"parameter_set"``, whose
    own elements then stand for ``"model"``), a :class:`ModelSpec` or a model-file path. Every source is built
    the same way: through the :class:`ModelSpec` it describes (parameters via ``spec_from_params``).
    ``scheme`` (fractional operator): 'default' (sum of exponentials), 'paper' (GL, N_t = 200,
    h = 1 ms) or 'gl' / ``{"name": "gl", "n_terms": N_t, "h": h}``. A dict spec may carry its own
    ``"scheme"``.

    ``friction_reversal_threshold`` [m] (>= 0, default 0 = the paper's rule): reversal deadband of every
    Berg element of the model (see :mod:`.friction`: set it a few times the displacement noise RMS when
    the model is driven by a measured displacement); no effect on models without friction. A dict spec
    may carry its own ``"friction_reversal_threshold"``; a ``"berg"`` element of a parallel spec may set
    its own ``"reversal_threshold"``, which wins.
    """
    if not (isinstance(dt, (int, float, np.floating)) and np.isfinite(dt) and dt > 0):
        raise ValueError(f'sample period dt must be a finite number > 0, got {dt!r}')
    if isinstance(params_or_spec, dict):
        scheme = params_or_spec.get('scheme', scheme)
        friction_reversal_threshold = params_or_spec.get('friction_reversal_threshold', friction_reversal_threshold)
    friction_reversal_threshold = _check_threshold(friction_reversal_threshold)
    spec = _model_spec(params_or_spec)
    if spec is None:   # a parameter set, a temperature or explicit values: described by their ModelSpec
        return _parallel(resolve_params(params_or_spec), float(dt), scheme, friction_reversal_threshold)
    return ParallelModel(spec.build_elements(float(dt), friction_reversal_threshold, scheme), dt,
                         spec.name or 'parallel', spec)
