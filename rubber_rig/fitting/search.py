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

"""The search of a model fit: the blocks' measured targets, the coordinates the optimisers see, and the global
search on the blocks' first harmonics (`rubber_rig.fitting.modelfit` refines it on the loops).

Search coordinates. Every free parameter gets a coordinate the optimisers see: ln p for positive
parameters (scale free), p / scale for signed ones, p itself for fractional orders (0.05..1], and
ln(p - p_ref) for a parameter that must stay above another (K_inf >= K0). Search ranges scale with the
data (``SCALES``): stiffnesses with the measured K_dyn, forces with the measured force amplitude, lengths
with the displacement amplitude, times with the inverse measured frequencies.

Harmonic objective: seed 000 Eq. 28-29 with the model's first harmonics (w_K e_K^2 + w_C e_C^2 per block), a
vectorised differential evolution over the whole population, then least squares. The load cell's delay d can be
a parameter (K e^{-jwd}).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import differential_evolution, least_squares

from rubber_rig.models.modelfile import ModelSpec

from .blocks import harmonic_sigma

DELAY = 'load_cell_delay'


@dataclass
class BlockTargets:
    """Measured block properties (SI) with their noise sigmas (relative, from the load-cell noise)."""

    frequency: np.ndarray
    amplitude: np.ndarray
    mean: np.ndarray
    k_dyn: np.ndarray
    c_eq: np.ndarray
    rel_sigma_k: np.ndarray
    rel_sigma_c: np.ndarray
    delay: np.ndarray | float = 0.0     # known load-cell delay [s] of each block's recording (calibration)

    @classmethod
    def from_blocks(cls, blocks, noise: dict, delays: dict | None = None):
        """``noise``: recording name -> load-cell noise sigma [N] (`blocks.harmonic_sigma` makes it the
        blocks' K_dyn and C_eq sigmas). ``delays``: recording name -> known load-cell delay [s].
        """
        get = {k: np.array([getattr(b, k) for b in blocks], float)
               for k in ('frequency', 'amplitude', 'mean', 'k_dyn', 'c_eq')}
        n = np.array([b.stop - b.start for b in blocks], float)
        sk, sc = harmonic_sigma([noise.get(b.recording, 0.0) for b in blocks], n, get['amplitude'], get['frequency'])
        delay = np.array([(delays or {}).get(b.recording, 0.0) for b in blocks], float)
        # |C_eq|: a block whose loss comes out negative (noise, a late load cell) still has its sigma
        return cls(**get, rel_sigma_k=sk / get['k_dyn'], rel_sigma_c=sc / np.maximum(np.abs(get['c_eq']), 1e-30),
                   delay=delay)

    def __len__(self):
        return self.frequency.size


# ---- search coordinates ----------------------------------------------------------------------------

def _scales(t: BlockTargets, dt: float) -> dict:
    kmax, kmin = float(t.k_dyn.max()), float(t.k_dyn.min())
    amax = float(t.amplitude.max())
    reach = float(np.max(t.amplitude + np.abs(t.mean)))
    fmin, fmax = float(t.frequency.min()), float(t.frequency.max())
    fmax_force = float(np.max(t.k_dyn * t.amplitude))
    wmin, wmax = 2 * np.pi * fmin, 2 * np.pi * fmax
    # kind -> (scale, lo, hi): log coordinates search [lo, hi]; signed ones [-hi, hi] x scale
    return {
        'stiffness': (kmax, 1e-3 * kmin, 3.0 * kmax),
        'force': (fmax_force, 1e-3 * fmax_force, 5.0 * fmax_force),
        'length': (amax, 1e-2 * amax, 50.0 * amax),
        'thickness': (reach, 1.02 * reach, 1e3 * reach),
        'time': (1.0 / wmin, 1e-2 / wmax, 1e2 / wmin),
        'damping': (kmax / wmin, 1e-5 * kmax / wmax, 10.0 * kmax / wmin),
        'k2': (kmax / amax, None, 30.0),
        'k3': (kmax / amax ** 2, None, 30.0),
        'k5': (kmax / amax ** 4, None, 30.0),
        'frac_alpha': (kmax, 1e-5 * kmax / wmax, 10.0 * kmax * max(1.0, 1.0 / wmin)),
        'frac_beta': (kmax, 1e-5 * kmax / wmax, 10.0 * kmax * max(1.0, 1.0 / wmin)),
        'slowness': (1.0 / (wmax * amax), 1e-1 / (wmax * amax), 1e4 / (wmin * amax)),
        'order': (1.0, 0.05, 1.0),
        'delay': (dt, -2e-3, 2e-3),
    }


@dataclass
class Coordinates:
    """The optimiser's coordinates of the free parameters (see the module docstring)."""

    names: list
    kinds: list          # 'log' | 'lin' | 'order' | 'above' | 'delay'
    scales: list
    ref: list            # index of the parameter an 'above' one must exceed, else None
    lo: np.ndarray
    hi: np.ndarray

    def values(self, z) -> dict:
        """Physical values of coordinates ``z`` (shape (n,) or (n, S)): name -> float or array (S, 1)."""
        z = np.asarray(z, float)
        col = (lambda v: v[:, None]) if z.ndim == 2 else (lambda v: float(v))
        raw = {}
        for i, (name, kind, s) in enumerate(zip(self.names, self.kinds, self.scales, strict=True)):
            if kind == 'log':
                raw[name] = np.exp(z[i])
            elif kind in ('lin', 'delay'):
                raw[name] = z[i] * s
            elif kind == 'order':
                raw[name] = z[i]
        for i, name in enumerate(self.names):
            if self.kinds[i] == 'above':
                raw[name] = raw[self.names[self.ref[i]]] + np.exp(z[i])
        return {k: col(v) for k, v in raw.items()}

    def z_of(self, values: dict) -> np.ndarray:
        z = np.empty(len(self.names))
        for i, (name, kind, s) in enumerate(zip(self.names, self.kinds, self.scales, strict=True)):
            v = float(values[name])
            if kind == 'log':
                z[i] = math.log(v)
            elif kind in ('lin', 'delay'):
                z[i] = v / s
            elif kind == 'order':
                z[i] = v
            else:
                z[i] = math.log(max(v - float(values[self.names[self.ref[i]]]), 1e-9 * abs(v)))
        return np.clip(z, self.lo, self.hi)


def coordinates(spec: ModelSpec, t: BlockTargets, dt: float, delay: bool = False) -> Coordinates:
    """Search coordinates and ranges of the free parameters of ``spec`` for the data ``t``."""
    sc = _scales(t, dt)
    names, kinds, scales, refs, lo, hi = [], [], [], [], [], []
    free = [n for n, _, _ in spec.free()]
    for name in free:
        p = spec.param_spec(name)
        scale, a, b = sc[p.scale]
        ref = None
        if p.scale == 'order':
            kind, zlo, zhi = 'order', max(a, p.lower or a), min(b, p.upper or b)
        elif p.signed:
            kind, zlo, zhi = 'lin', -b, b
        elif p.above and _sibling(spec, name, p.above) in free:
            kind, ref = 'above', free.index(_sibling(spec, name, p.above))
            zlo, zhi = math.log(1e-4 * sc['stiffness'][0]), math.log(b)
        else:
            kind, zlo, zhi = 'log', math.log(a), math.log(b)
        names.append(name)
        kinds.append(kind)
        scales.append(scale)
        refs.append(ref)
        lo.append(zlo)
        hi.append(zhi)
    if delay:
        _, a, b = sc['delay']
        # the estimated delay adds to the declared one; the total is never negative (a load cell cannot measure
        # a force before it acts): a model that lags the specimen asks for one, and it must show as a misfit
        declared = float(np.min(t.delay)) if np.size(t.delay) else 0.0
        a = max(a, -declared)
        names.append(DELAY)
        kinds.append('delay')
        scales.append(dt)
        refs.append(None)
        lo.append(a / dt)
        hi.append(b / dt)
    return Coordinates(names, kinds, scales, refs, np.array(lo), np.array(hi))


def _sibling(spec, name, other):
    """The model's name of parameter ``other`` of the element that has parameter ``name``."""
    prefix = name.rpartition('.')[0]
    for n, _, p in spec.parameters():
        if p == other and n.rpartition('.')[0] == prefix:
            return n
    return other


# ---- harmonic objective ----------------------------------------------------------------------------

def harmonic_residuals(z, spec: ModelSpec, coords: Coordinates, t: BlockTargets, w_k=100.0, w_c=1.0):
    """Seed 000 Eq. 28 residuals sqrt(w) e with the model's first harmonics as the load cell sees them (known
    delay ``t.delay`` plus an estimated one); z (n,) -> (2B,), (n, S) -> (S, 2B).
    """
    v = coords.values(z)
    w = 2 * np.pi * t.frequency
    d = v.pop(DELAY, 0.0) + t.delay
    with np.errstate(all='ignore'):
        k = spec.first_harmonic(t.frequency, t.amplitude, t.mean, v) * np.exp(-1j * w * d)
        e_k = np.abs(k) / t.k_dyn - 1.0
        e_c = (k.imag / w) / t.c_eq - 1.0
    r = np.concatenate([np.sqrt(w_k) * e_k, np.sqrt(w_c) * e_c], axis=-1)
    return np.where(np.isfinite(r), r, 1e3)


def fit_harmonic_model(spec, coords, t, w_k=100.0, w_c=1.0, seed=0, maxiter=300, popsize=15, start=None):
    """Global search (differential evolution, vectorised) + least squares. Returns (z, least_squares result)."""
    bounds = list(zip(coords.lo, coords.hi, strict=True))

    def cost(z):
        r = harmonic_residuals(z, spec, coords, t, w_k, w_c)
        return np.sum(r * r, axis=-1)

    x0 = None if start is None else coords.z_of(start)
    de = differential_evolution(cost, bounds, seed=seed, maxiter=maxiter, popsize=popsize, tol=1e-8,
                                polish=False, vectorized=True, updating='deferred', x0=x0)
    ls = least_squares(harmonic_residuals, de.x, bounds=(coords.lo, coords.hi), args=(spec, coords, t, w_k, w_c),
                       method='trf', xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=2000)
    return ls.x, ls
