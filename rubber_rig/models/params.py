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

"""Parameter sets of the rubber-element models, in SI, with validation and temperature interpolation.

The swing-arm rubber joint of seed 000 (Table 1 at 20, 0, -20, -40 degC and the Table 2 variants) ships as
YAML in ``data/swing_arm_joint.yaml``; each set stores its model type, SI values, the temperature it was
identified at and its source (REFERENCES.md names the papers). Model types have physics names
(``fractional_zener_berg``, ``tangent_maxwell_berg``, ``kelvin_voigt``); the earlier names (``seed000``,
``seed001``, ``seed000_20C``...) stay readable as aliases because recordings and fit files carry them.

Temperature interpolation (:func:`parameters_at_temperature`): shape-preserving monotone cubic
Hermite interpolation (PCHIP, Fritsch-Carlson) of each parameter over the four table temperatures,
on transformed coordinates that keep every interpolant physically valid:

* K0, alpha: PCHIP of the value;
* K_inf: PCHIP of log(K_inf - K0), added to the interpolated K0, so K_inf > K0 always and K_inf is
  monotone wherever both K0 and K_inf - K0 are;
* tau, x2, F_fmax: PCHIP of the logarithm (tau follows an Arrhenius/WLF-like shift, and all three
  stay positive).

PCHIP is C1, reproduces the table exactly at the table temperatures, never overshoots (between two
table temperatures each parameter stays between its two table values, so alpha stays in (0, 1])
and is monotone on every interval where the data are. Outside [-40, 20] degC it refuses to
extrapolate (ValueError).
"""
from __future__ import annotations

import dataclasses
import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import yaml
from scipy.interpolate import PchipInterpolator

from .yamlfile import read_yaml_file

DATA_DIR = Path(__file__).resolve().parent / 'data'


class ParameterValueError(ValueError):
    """A model parameter with an invalid value; ``parameter`` is its name ('alpha', 'temperature'), so a
    caller can point at the setting it came from without parsing the message.
    """

    def __init__(self, parameter: str, why: str):
        super().__init__(f'parameter {parameter} {why}')
        self.parameter = parameter


def _check_finite(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterValueError(name, f'must be a number, got {value!r}') from None
    if not math.isfinite(v):
        raise ParameterValueError(name, f'must be finite, got {v}')
    return v


def _check_positive(name: str, value) -> float:
    v = _check_finite(name, value)
    if v <= 0.0:
        raise ParameterValueError(name, f'must be > 0, got {v}')
    return v


def _check_order(name: str, value) -> float:
    v = _check_finite(name, value)
    if not 0.0 < v <= 1.0:
        raise ParameterValueError(name, f'(fractional order) must be in (0, 1], got {v}')
    return v


class _Params:
    """Shared behaviour of the frozen parameter dataclasses."""

    @classmethod
    def names(cls) -> tuple:
        return tuple(f.name for f in dataclasses.fields(cls))

    def as_dict(self) -> dict:
        return {n: float(getattr(self, n)) for n in self.names()}

    @classmethod
    def from_dict(cls, values: dict):
        unknown = set(values) - set(cls.names())
        missing = set(cls.names()) - set(values)
        if unknown:
            raise ValueError(f'unknown parameter(s) for {cls.__name__}: {sorted(unknown)}')
        if missing:
            raise ValueError(f'missing parameter(s) for {cls.__name__}: {sorted(missing)}')
        p = cls(**{k: _check_finite(k, v) for k, v in values.items()})
        p.validate()
        return p


@dataclasses.dataclass(frozen=True)
class ZenerBergParams(_Params):
    """Fractional-derivative Zener element (seed 000 Eq. 4) in parallel with Berg friction (seed 000 Eq. 16).

    k0 [N/m] static stiffness, k_inf [N/m] high-frequency storage stiffness, tau [s] relaxation
    time, alpha [-] fractional order in (0, 1], x2 [m] displacement to reach F_fmax/2 from the
    virgin state, f_fmax [N] maximum friction force.
    """

    k0: float
    k_inf: float
    tau: float
    alpha: float
    x2: float
    f_fmax: float

    def validate(self) -> 'ZenerBergParams':
        for n in ('k0', 'k_inf', 'tau', 'x2', 'f_fmax'):
            _check_positive(n, getattr(self, n))
        _check_order('alpha', self.alpha)
        if self.k_inf < self.k0:
            raise ParameterValueError('k_inf', f'({self.k_inf:g} N/m) must be >= k0 ({self.k0:g} N/m)')
        return self


@dataclasses.dataclass(frozen=True)
class KelvinVoigtParams(_Params):
    """Kelvin-Voigt element: k [N/m] spring parallel to c [N s/m] dashpot (seed 000 Table 2 case 1)."""

    k: float
    c: float

    def validate(self) -> 'KelvinVoigtParams':
        _check_positive('k', self.k)
        v = _check_finite('c', self.c)
        if v < 0:
            raise ParameterValueError('c', f'must be >= 0, got {v}')
        return self


@dataclasses.dataclass(frozen=True)
class TangentMaxwellBergParams(_Params):
    """Seed 001's combined model: Dzierzek tangent spring + two Maxwell branches + Berg friction.

    k_t [N/m] tangent stiffness at x = 0, d_t [m] characteristic thickness (asymptote of the
    elastic curve), k1, k2 [N/m] and c1, c2 [N s/m] the two Maxwell branches, f_fmax [N], x2 [m]
    Berg friction. (The paper's 10 parameters count the p, q, r sub-parameters of an
    amplitude-dependent k_t fitted to static tests; the time-domain model uses k_t itself.)
    """

    k_t: float
    d_t: float
    k1: float
    c1: float
    k2: float
    c2: float
    f_fmax: float
    x2: float

    def validate(self) -> 'TangentMaxwellBergParams':
        for n in self.names():
            _check_positive(n, getattr(self, n))
        return self


PARAM_CLASSES = {'fractional_zener_berg': ZenerBergParams, 'kelvin_voigt': KelvinVoigtParams,
                 'tangent_maxwell_berg': TangentMaxwellBergParams}
# Model type names of files written before the physics names.
MODEL_ALIASES = {'seed000': 'fractional_zener_berg', 'seed001': 'tangent_maxwell_berg'}


def canonical_model(name) -> str:
    """The physics name of a model type (``'seed000'`` -> ``'fractional_zener_berg'``); unknown names unchanged."""
    return MODEL_ALIASES.get(name, name)


def model_class(name):
    """The parameter dataclass of a model type name or alias; ValueError naming the known types."""
    try:
        return PARAM_CLASSES[canonical_model(name)]
    except (KeyError, TypeError):
        raise ValueError(f'unknown model {name!r}; known: {", ".join(PARAM_CLASSES)} '
                         f'(or the earlier names {", ".join(MODEL_ALIASES)})') from None


@lru_cache(maxsize=None)
def _load_yaml(name: str) -> dict:
    with open(DATA_DIR / name, encoding='utf-8') as fh:
        return yaml.safe_load(fh)


def sets_with_aliases(data: dict) -> dict:
    """The ``sets`` of a parameter file's YAML plus its ``aliases`` (old name -> set name) as extra keys."""
    sets = dict(data.get('sets') or {})
    for old, new in (data.get('aliases') or {}).items():
        if new in sets:
            sets.setdefault(old, sets[new])
    return sets


def _shipped_files() -> list:
    return [_load_yaml(path.name) for path in sorted(DATA_DIR.glob('*.yaml'))]


def _all_sets() -> dict:
    sets = {}
    for data in _shipped_files():
        sets.update(sets_with_aliases(data))
    return sets


def list_parameter_sets() -> list:
    """Names of the shipped parameter sets, e.g. ``['swing_arm_joint_0C', 'swing_arm_joint_20C', ...]``
    (without the aliases of earlier names).
    """
    return sorted(name for data in _shipped_files() for name in data.get('sets', {}))


def read_parameter_file(path) -> dict:
    """The YAML of a parameter file in the shipped layout (``sets:`` name -> {model, values, temperature,
    source}; optional ``temperature_series`` and ``aliases``), e.g. the output of ``rubber-rig fit``.
    Errors name the file and what is wrong.
    """
    path = Path(path).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f'no such parameter file: {path}')
    data = read_yaml_file(path) or {}    # one-line ValueError: unreadable, binary, not YAML
    sets = data.get('sets') if isinstance(data, dict) else None
    if not isinstance(sets, dict) or not sets:
        raise ValueError(f'{path}: no "sets" mapping of parameter sets '
                         '(the layout of rubber_rig/models/data/swing_arm_joint.yaml)')
    return data


def _resolve_set(name: str) -> tuple:
    """(set name, {model, values}) of a shipped set name, ``FILE.yaml`` (one set) or ``FILE.yaml:SET``."""
    file_part, _, set_part = str(name).rpartition(':')
    if not file_part and set_part.endswith(('.yaml', '.yml')):
        file_part, set_part = set_part, ''
    if file_part:
        sets = sets_with_aliases(read_parameter_file(file_part))
        if not set_part:
            if len(sets) != 1:
                raise ValueError(f'{file_part} holds {len(sets)} parameter sets; name one as '
                                 f'{file_part}:SET with SET one of {", ".join(sorted(sets))}')
            set_part = next(iter(sets))
        origin = file_part
    else:
        sets, origin = _all_sets(), 'the shipped sets'
    if set_part not in sets:
        raise ValueError(f'unknown parameter set {set_part!r} in {origin}; known: {", ".join(sorted(sets))}')
    entry = sets[set_part]
    if not isinstance(entry, dict) or canonical_model(entry.get('model')) not in PARAM_CLASSES \
            or not isinstance(entry.get('values'), dict):
        raise ValueError(f'parameter set {set_part!r} in {origin} needs "model" (one of '
                         f'{", ".join(PARAM_CLASSES)}) and a "values" mapping')
    return set_part, entry


def load_parameter_set(name: str):
    """Parameter set by name, as a validated frozen dataclass in SI units.

    ``swing_arm_joint_20C``, ``_0C``, ``_m20C``, ``_m40C`` (seed 000 Table 1) and ``swing_arm_joint_case2`` ..
    ``_case9`` (Table 2) give :class:`ZenerBergParams`; ``swing_arm_joint_case1`` (the paper's Kelvin-Voigt
    reference) gives :class:`KelvinVoigtParams`. The earlier names (``seed000_20C``...) are aliases.
    ``name`` may also be a YAML file in the same layout (the output of ``rubber-rig fit``):
    ``FILE.yaml`` when it holds one set, ``FILE.yaml:SET`` to pick one.
    """
    _, entry = _resolve_set(name)
    return model_class(entry['model']).from_dict(entry['values'])


def parameter_set_info(name: str) -> dict:
    """What a parameter set's file says about it: ``model`` (physics name), ``temperature`` [degC] it was
    identified at (NaN when the file gives none) and ``source``.
    """
    set_name, entry = _resolve_set(name)
    t = entry.get('temperature')
    return {'name': set_name, 'model': canonical_model(entry['model']),
            'temperature': math.nan if t is None else _check_finite('temperature', t),
            'source': str(entry.get('source', ''))}


@lru_cache(maxsize=None)
def _temperature_interpolants():
    data = _load_yaml('swing_arm_joint.yaml')
    rows = sorted((data['sets'][name] for name in data['temperature_series']), key=lambda r: r['temperature'])
    t = np.array([r['temperature'] for r in rows])
    col = {k: np.array([float(r['values'][k]) for r in rows]) for k in ZenerBergParams.names()}
    return t, {
        'k0': PchipInterpolator(t, col['k0']),
        'log_dk': PchipInterpolator(t, np.log(col['k_inf'] - col['k0'])),
        'log_tau': PchipInterpolator(t, np.log(col['tau'])),
        'alpha': PchipInterpolator(t, col['alpha']),
        'log_x2': PchipInterpolator(t, np.log(col['x2'])),
        'log_f_fmax': PchipInterpolator(t, np.log(col['f_fmax'])),
    }


def parameters_at_temperature(t_degC: float) -> ZenerBergParams:  # noqa: N803 - the unit is part of the name
    """Seed 000 parameters at temperature ``t_degC`` [degC], interpolated from Table 1.

    Exact at 20, 0, -20, -40 degC; monotone PCHIP in between (see the module docstring).
    Raises ValueError outside [-40, 20] degC.
    """
    t = _check_finite('temperature', t_degC)
    temps, f = _temperature_interpolants()
    if not temps[0] <= t <= temps[-1]:
        raise ParameterValueError('temperature', f'{t:g} degC is outside the identified range '
                                  f'[{temps[0]:g}, {temps[-1]:g}] degC of seed 000 Table 1')
    k0 = float(f['k0'](t))
    p = ZenerBergParams(k0=k0, k_inf=k0 + float(np.exp(f['log_dk'](t))), tau=float(np.exp(f['log_tau'](t))),
                        alpha=float(f['alpha'](t)), x2=float(np.exp(f['log_x2'](t))),
                        f_fmax=float(np.exp(f['log_f_fmax'](t))))
    return p.validate()
