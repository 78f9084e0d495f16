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

"""The element catalogue: every element type a model file may use, with its parameters, units and sources.

One :class:`ElementType` per type names its parameters (:class:`ParamSpec`: SI unit, the unit
dimension a model file may write it in, how a fit scales its search range), the equation it
implements, a factory for the streaming/batch element and its first harmonic: the complex stiffness
K1 = (first harmonic of the force) / (first harmonic of the displacement) [N/m] under
x = mean + A sin(wt) in steady state, exact for every type (closed form or quadrature). The elements
of a model act in parallel (seed 000 Eq. 1), and the first harmonic of a sum is the sum of the first
harmonics, so K_dyn = |sum K1| and C_eq = Im(sum K1) / w of any model are exact without running it
(only the first harmonic does work against a sine, so the loop energy is pi A^2 Im K1).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from . import elements as el
from .fractional import two_order_complex_stiffness, zener_complex_stiffness
from .friction import BergFriction, SmoothCoulomb, friction_first_harmonic
from .pad import EllipticDamping, OperatingPointSpring, elliptic_first_harmonic

# uniform nodes over one period: the trapezoid rule is exact for trigonometric polynomials of lower degree,
# so polynomial springs up to degree 63 are exact and smooth laws (tan, tanh) converge geometrically
_N_QUAD = 64
_THETA = (np.arange(_N_QUAD) + 0.5) * 2 * np.pi / _N_QUAD
_SIN, _COS = np.sin(_THETA), np.cos(_THETA)


@dataclass(frozen=True)
class ParamSpec:
    """One parameter of an element type.

    ``dimension``: the :mod:`rubber_rig.units` dimension a model file may write it in (``'number'``: SI
    only). ``scale``: what sets its search range in a fit (see ``rubber_rig.fitting.modelfit``).
    ``signed``: may be zero or negative (fitted on a linear scale, else on a log scale). ``upper``: a
    hard upper limit (orders <= 1); ``lower`` a hard lower one (the fractional Zener's order, whose time-domain
    scheme is accurate from 0.1). ``optional``: absent from a file means 0 and not part of the model.
    ``above``: a parameter of the same element this one must not fall below (K_inf >= K0).
    """

    name: str
    unit: str
    dimension: str
    doc: str
    scale: str
    signed: bool = False
    upper: float | None = None
    optional: bool = False
    lower: float | None = None
    above: str | None = None


@dataclass(frozen=True)
class ElementType:
    name: str
    summary: str
    source: str
    params: tuple
    build: Callable                      # (values {name: SI float}, dt [s], options) -> element
    first_harmonic: Callable             # (values {name: array}, frequency, amplitude, mean) -> complex array
    kind: str                            # elastic | viscous | friction | viscoelastic
    options: dict = field(default_factory=dict)   # name -> doc of settings that are not fitted
    aliases: tuple = ()

    def param(self, name) -> ParamSpec:
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(name)

    def describe(self) -> dict:
        return {'type': self.name, 'summary': self.summary, 'source': self.source, 'kind': self.kind,
                'aliases': list(self.aliases),
                'parameters': [{'name': p.name, 'unit': p.unit, 'doc': p.doc, 'optional': p.optional,
                                'signed': p.signed} for p in self.params],
                'options': dict(self.options)}


def _stiffness(name, doc, **kw):
    return ParamSpec(name, 'N/m', 'stiffness', doc, 'stiffness', **kw)


def _quad_elastic(force, amplitude, mean):
    """First harmonic [N/m] of a memoryless elastic law ``force(x)`` under x = mean + A sin(theta)."""
    a = np.asarray(amplitude, float)[..., None]
    x = np.asarray(mean, float)[..., None] + a * _SIN
    return (2.0 / _N_QUAD) * np.sum(force(x) * _SIN, axis=-1) / a[..., 0] + 0j


_POLY_TERMS = (('preload', 0), ('k1', 1), ('k2', 2), ('k3', 3), ('k5', 5))   # parameter -> power of x


def _poly_force(v, x):
    out = 0.0
    for name, power in _POLY_TERMS:
        c = v.get(name)
        if c is not None:
            out = out + np.asarray(c, float)[..., None] * x ** power
    return out


def _poly_fh(v, f, a, m):
    return _quad_elastic(lambda x: _poly_force(v, x), a, m)


def _poly_build(v, dt, opts):
    coeffs = [0.0] * 6
    for name, power in _POLY_TERMS:
        coeffs[power] = float(v.get(name, 0.0))
    while len(coeffs) > 1 and coeffs[-1] == 0.0:
        coeffs.pop()
    return el.PolynomialSpring(coeffs)


def _tan_force(v, x):
    kt, dt_ = (np.asarray(v[k], float)[..., None] for k in ('k_t', 'd_t'))
    r = np.clip(x / dt_, -0.999999, 0.999999)    # a fit may try d_t below the amplitude: finite, huge force
    return 2 * kt * dt_ / np.pi * np.tan(np.pi * r / 2)


def _tanh_fh(v, f, a, m):
    fc, s = (np.asarray(v[k], float)[..., None] for k in ('f_c', 'a'))
    amp = np.asarray(a, float)[..., None]
    vel = 2 * np.pi * np.asarray(f, float)[..., None] * amp * _COS
    return 1j * (2.0 / _N_QUAD) * np.sum(fc * np.tanh(s * vel) * _COS, axis=-1) / amp[..., 0]


def _zener_fh(v, f, a, m):
    w = 2 * np.pi * np.asarray(f, float)
    return zener_complex_stiffness(w, *(np.asarray(v[k], float) for k in ('k0', 'k_inf', 'tau', 'alpha'))) + 0 * a


def fractional_element(k0, k_inf, tau, alpha, dt, scheme='default'):
    """The fractional Zener element with the fractional operator ``scheme``: 'default' (sum of exponentials),
    'paper' (GL, N_t = 200, h = 1 ms, seed 000 Eq. 15) or 'gl' / {"name": "gl", "n_terms": N_t, "h": h}.
    """
    opts = dict(scheme) if isinstance(scheme, dict) else {'name': scheme}
    name = opts.pop('name', 'default')
    if name == 'default':
        return el.FractionalZener(k0, k_inf, tau, alpha, dt, **opts)
    if name in ('gl', 'paper'):
        if name == 'paper':   # seed 000 Eq. 15: N_t = 200, h = 1 ms
            opts = {'n_terms': 200, 'h': 1e-3, **opts}
        return el.FractionalZenerGL(k0, k_inf, tau, alpha, dt, **opts)
    raise ValueError(f"unknown fractional scheme {name!r}: use 'default', 'gl' or 'paper'")


def _zener_build(v, dt, opts):
    return fractional_element(v['k0'], v['k_inf'], v['tau'], v.get('alpha', 1.0), dt, opts.get('scheme', 'default'))


_ORDER = dict(unit='-', dimension='number', scale='order', upper=1.0)
_REVERSAL = {'reversal_threshold': "Berg's reversal deadband [m] (see rubber_rig.models.friction); "
                                   'a fit sets it from the displacement noise'}

TYPES = {t.name: t for t in (
    ElementType(
        'fractional_zener', 'fractional-derivative Zener element: K0 parallel to a fractional Maxwell branch',
        'seed 000 Eq. 4 (complex stiffness Eq. 11)',
        (_stiffness('k0', 'static stiffness'),
         _stiffness('k_inf', 'high-frequency stiffness', above='k0'),
         ParamSpec('tau', 's', 'time', 'relaxation time', 'time'),
         ParamSpec('alpha', doc='fractional order in [0.1, 1] (where the time-domain scheme keeps its stated '
                   'accuracy, rubber_rig.models.fractional)', lower=0.1, **_ORDER)),
        _zener_build, _zener_fh, 'viscoelastic',
        {'scheme': "fractional operator: 'default' (sum of exponentials), 'paper' (GL, N_t = 200, h = 1 ms), 'gl'"}),
    ElementType(
        'zener', 'standard linear solid: K0 parallel to a Maxwell branch (K_inf - K0, tau)',
        'seed 000 Eq. 4, alpha = 1',
        (_stiffness('k0', 'static stiffness'), _stiffness('k_inf', 'high-frequency stiffness', above='k0'),
         ParamSpec('tau', 's', 'time', 'relaxation time', 'time')),
        _zener_build, lambda v, f, a, m: _zener_fh({**v, 'alpha': 1.0}, f, a, m), 'viscoelastic'),
    ElementType(
        'berg', "Berg's smooth friction with reference-state update on velocity reversal",
        'seed 000 Eq. 16-18; seed 001 Eq. 3',
        (ParamSpec('x2', 'm', 'length', 'displacement from the virgin state to F_fmax / 2', 'length'),
         ParamSpec('f_fmax', 'N', 'force', 'maximum friction force', 'force')),
        lambda v, dt, o: BergFriction(v['f_fmax'], v['x2'], dt, o.get('reversal_threshold', 0.0)),
        lambda v, f, a, m: friction_first_harmonic(np.asarray(v['f_fmax'], float), np.asarray(v['x2'], float),
                                                   np.asarray(a, float)) + 0 * np.asarray(f, float),
        'friction', dict(_REVERSAL)),
    ElementType(
        'polynomial_spring', 'polynomial elastic force preload + k1 x + k2 x^2 + k3 x^3 + k5 x^5 '
        '(write only the terms the element has)', 'seed 003 Eq. 4; seed 004 Eq. 5 (odd terms)',
        (ParamSpec('preload', 'N', 'force', 'constant force (preload) at x = 0', 'force', signed=True, optional=True),
         _stiffness('k1', 'linear stiffness', signed=True, optional=True),
         ParamSpec('k2', 'N/m^2', 'stiffness2', 'quadratic coefficient', 'k2', signed=True, optional=True),
         ParamSpec('k3', 'N/m^3', 'stiffness3', 'cubic coefficient', 'k3', signed=True, optional=True),
         ParamSpec('k5', 'N/m^5', 'stiffness5', 'fifth-order coefficient', 'k5', signed=True, optional=True)),
        _poly_build, _poly_fh, 'elastic'),
    ElementType(
        'linear_spring', 'linear spring F = k x', 'seed 000 Table 2 case 1',
        (_stiffness('k', 'stiffness'),),
        lambda v, dt, o: el.LinearSpring(v['k']), lambda v, f, a, m: np.asarray(v['k'], float) + 0j * a, 'elastic'),
    ElementType(
        'dzierzek', "Dzierzek's non-linear elastic spring, tangent law F = 2 k_t d_t / pi tan(pi x / (2 d_t))",
        'seed 001 Eq. 6 (first line) / Eq. 19',
        (_stiffness('k_t', 'slope at x = 0'),
         ParamSpec('d_t', 'm', 'length', 'characteristic thickness: the asymptote of the elastic curve', 'thickness')),
        lambda v, dt, o: el.TangentSpring(v['k_t'], v['d_t']),
        lambda v, f, a, m: _quad_elastic(lambda x: _tan_force(v, x), a, m), 'elastic', aliases=('tangent_spring',)),
    ElementType(
        'two_order_fractional', 'two-order fractional viscoelastic model (static stiffness k1)',
        'seed 003 Eq. 22 (complex stiffness Eq. 25/26)',
        (_stiffness('k1', 'static stiffness'), _stiffness('k2', 'stiffness of the fractional branch'),
         ParamSpec('c1', 'N s^beta/m', 'number', 'fractional coefficient of order beta (SI only)', 'frac_beta'),
         ParamSpec('c2', 'N s^alpha/m', 'number', 'fractional coefficient of order alpha (SI only)', 'frac_alpha'),
         ParamSpec('alpha', doc='fractional order in (0, 1]', **_ORDER),
         ParamSpec('beta', doc='fractional order in (0, 1]', **_ORDER)),
        lambda v, dt, o: el.TwoOrderFractional(v['k1'], v['k2'], v['c1'], v['c2'], v['alpha'], v['beta'], dt),
        lambda v, f, a, m: two_order_complex_stiffness(
            2 * np.pi * np.asarray(f, float), *(np.asarray(v[k], float) for k in
                                                ('k1', 'k2', 'c1', 'c2', 'alpha', 'beta'))) + 0 * a,
        'viscoelastic'),
    ElementType(
        'elliptic_damping', 'elliptic damping force +-b sqrt(1 - ((x - x0)/A)^2), sign of the velocity; A and x0 '
        'from the last half cycle (or fixed)', 'seed 004 Eq. 2-4',
        (ParamSpec('b', 'N', 'force', 'half height of the ellipse (b = E / (pi A), Eq. 3)', 'force'),),
        lambda v, dt, o: EllipticDamping(v['b'], dt, amplitude=o.get('amplitude'), center=o.get('center'),
                                         reversal_threshold=o.get('reversal_threshold', 0.0)),
        lambda v, f, a, m: elliptic_first_harmonic(np.asarray(v['b'], float), f, a), 'viscous',
        {'amplitude': 'fixed ellipse half width A [m] (default: from the motion)',
         'center': 'fixed ellipse centre x0 [m] (default: from the motion)', **_REVERSAL}),
    ElementType(
        'maxwell', 'Maxwell branch: spring k in series with dashpot c', 'seed 001 Eq. 6 (viscous part)',
        (_stiffness('k', 'spring stiffness'), ParamSpec('c', 'N s/m', 'damping', 'dashpot coefficient', 'damping')),
        lambda v, dt, o: el.Maxwell(v['k'], v['c'], dt),
        lambda v, f, a, m: _maxwell_fh(v, f) + 0 * a, 'viscous'),
    ElementType(
        'dashpot', 'viscous dashpot F = c v', 'seed 000 Table 2 case 1',
        (ParamSpec('c', 'N s/m', 'damping', 'damping coefficient', 'damping'),),
        lambda v, dt, o: el.Dashpot(v['c'], dt),
        lambda v, f, a, m: 2j * np.pi * np.asarray(f, float) * np.asarray(v['c'], float) + 0 * a, 'viscous'),
    ElementType(
        'tanh_coulomb', 'smooth Coulomb friction F = f_c tanh(a v)', 'seed 002 Eq. 46',
        (ParamSpec('f_c', 'N', 'force', 'friction force level', 'force'),
         ParamSpec('a', 's/m', 'slowness', 'steepness of the tanh in velocity', 'slowness')),
        lambda v, dt, o: SmoothCoulomb(v['f_c'], v['a'], dt), _tanh_fh, 'friction', aliases=('smooth_coulomb',)),
)}
ALIASES = {a: t.name for t in TYPES.values() for a in t.aliases}

# Seed 004's pad with operating-point dependent coefficients (Eq. 5 and 7) is a specimen for the simulator; its
# coefficients are identified per block (rubber_rig.fitting.blocktrend), not as one parameter vector.
OPERATING_POINT_TYPES = {
    'operating_point_spring': ('odd polynomial K1(f, A) x + K3(f, A) x^3 + ... with coefficients that follow the '
                               'operating point (seed 004 Eq. 5, 7); k_odd: list of numbers or tables '
                               'c[i][j] (value = sum c_ij f^i A^j, SI)'),
}


def _maxwell_fh(v, f):
    k, c = np.asarray(v['k'], float), np.asarray(v['c'], float)
    s = 2j * np.pi * np.asarray(f, float) * c / k
    return k * s / (1 + s)


def element_type(name: str) -> ElementType:
    """The catalogue entry of a type name or alias; ValueError naming the known types."""
    key = ALIASES.get(name, name)
    if key not in TYPES:
        raise ValueError(f'unknown element type {name!r}; known: {", ".join(sorted(TYPES))} '
                         f'(and {", ".join(OPERATING_POINT_TYPES)})')
    return TYPES[key]


def build_operating_point_spring(values: dict, dt: float):
    """Seed 004's operating-point spring from a model-file entry (SI; see ``OPERATING_POINT_TYPES``)."""
    opts = {k: values[k] for k in ('frequency', 'amplitude', 'reversal_threshold') if k in values}
    unknown = set(values) - {'k_odd', 'frequency', 'amplitude', 'reversal_threshold'}
    if unknown or 'k_odd' not in values:
        raise ValueError('operating_point_spring takes k_odd (list) and optional frequency, amplitude, '
                         f'reversal_threshold; got {sorted(values)}')
    return OperatingPointSpring(values['k_odd'], dt, **opts)


def catalogue() -> list:
    """Every element type as a plain dict (``rubber-rig models --json``)."""
    out = [t.describe() for t in TYPES.values()]
    out += [{'type': name, 'summary': doc, 'source': 'seed 004 Eq. 5, 7', 'kind': 'elastic', 'aliases': [],
             'parameters': [{'name': 'k_odd', 'unit': 'N/m, N/m^3, ...', 'doc': 'odd coefficients',
                             'optional': False, 'signed': True}], 'options': {}, 'fit': False}
            for name, doc in OPERATING_POINT_TYPES.items()]
    return out
