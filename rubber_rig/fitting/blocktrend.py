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

"""Seed 004's identification: per-block least squares of Eq. 6, then the operating-point trend (Eq. 7-12).

Per block (one excitation case, :class:`rubber_rig.fitting.blocks.BlockResult`) :func:`fit_block` solves the linear
least-squares problem

    F = offset + sum_k K_k x^k + b s(t) sqrt(max(0, 1 - ((x - x0) / A)^2))

over the block's analysed whole cycles: x is the *absolute* displacement [m] (a preload shows as its mean x0), s the
sign of the velocity, x0 and A the block's mean and amplitude. The paper identifies K1, K3 and b this way for each
case (Fig. 5, Table 2); the offset absorbs a load-cell zero error. Under a preload the columns 1, x, x^3 are nearly
collinear over the small range x0 +- A, so offset, K1 and K3 are strongly correlated: the correlations are reported
with the values.

:func:`fit_trend` then fits one identified coefficient across blocks by weighted least squares onto a table
c[i][j] (value = sum_ij c[i][j] f^i A^j, f [Hz], A [m], SI), the form :func:`rubber_rig.models.trend.trend_value`
evaluates (the paper's Eq. 7-8: quadratic in A with coefficients cubic in f). :func:`per_block_report` prints both
in the paper's units (mm, kN).

Uncertainties: the per-block sigmas come from the load-cell noise (:func:`rubber_rig.fitting.blocks.noise_level` of
the force unless given) and are scaled by sqrt(max(1, chi2/dof)), so a model that does not describe the loop within
the noise (e.g. a missing cubic term) gets wider, not overconfident, error bars. The trend's sigmas are scaled the
same way.
"""
from __future__ import annotations

import math

import numpy as np

from .blocks import noise_level

# paper units: value [SI] * factor = value [paper unit]
_KN = 1e-3          # kN per N
_MM = 1e3           # mm per m


# ------------------------------------------------------------------------------------------------- per block

def _velocity_sign(x, start, stop, frequency, dt):
    """Sign of the velocity on samples [start, stop) of the whole record ``x``: a centred difference over +-h
    samples of the displacement smoothed by a (2h + 1)-sample moving average, h about a 40th of the period.

    Both filters are symmetric, so the sign changes where the velocity does (no phase lag); samples outside the block
    are used where the record has them, and the indices are clipped at the ends of the record. Near the extremes noise
    may flip the sign, but the elliptic column is ~0 there (sqrt(2 d / A) at a distance d from the extreme).
    """
    n = x.size
    period = 1.0 / (frequency * dt) if frequency > 0 and dt > 0 else 0.0
    h = max(1, int(round(period / 40.0))) if math.isfinite(period) else 1
    lo, hi = max(0, start - 2 * h), min(n, stop + 2 * h)
    seg = x[lo:hi]
    if h > 1:
        kernel = np.ones(2 * h + 1) / (2 * h + 1)
        padded = np.concatenate([np.full(h, seg[0]), seg, np.full(h, seg[-1])])
        seg = np.convolve(padded, kernel, mode='valid')
    k = np.arange(start, stop) - lo
    ahead = np.minimum(k + h, seg.size - 1)
    behind = np.maximum(k - h, 0)
    return np.sign(seg[ahead] - seg[behind])


def _check_orders(orders):
    out = []
    for k in orders:
        if isinstance(k, bool) or int(k) != k or int(k) < 1:
            raise ValueError(f'orders must be powers >= 1 of the displacement, got {orders!r}')
        if int(k) in out:
            raise ValueError(f'orders lists power {int(k)} twice: {orders!r}')
        out.append(int(k))
    if not out:
        raise ValueError('orders is empty: at least one power of the displacement (e.g. (1, 3)) is needed')
    return tuple(out)


def fit_block(x, force, dt, block, orders=(1, 3), noise=None) -> dict:
    """Seed 004 Eq. 6 fitted to one block by linear least squares.

    Parameters
    ----------
    x, force : array
        The whole record's absolute displacement [m] and force [N]; samples block.start..block.stop are fitted.
    dt : float
        Sample period [s].
    block : BlockResult
        Its start, stop, frequency [Hz], amplitude A [m] and mean x0 [m] are used.
    orders : tuple of int
        Powers k of the displacement in the elastic polynomial (the paper: (1, 3) or (1, 3, 5)).
    noise : float or None
        Load-cell noise sigma [N]; None: :func:`noise_level` of the block's force.

    Returns
    -------
    dict
        'frequency', 'amplitude', 'mean' (the block's), 'K<k>' for k in orders [N/m^k], 'b' [N], 'offset' [N],
        'sigma' {name: 1 sigma}, 'correlation' {'A-B': r for every pair, e.g. 'K1-K3'}, 'chi2_per_dof',
        'residual_rms' [N], 'noise' [N], 'samples', 'dof', 'orders', 'index', 'recording', 'notes'.
    """
    orders = _check_orders(orders)
    x = np.asarray(x, dtype=float).reshape(-1)
    force = np.asarray(force, dtype=float).reshape(-1)
    start, stop = int(block.start), min(int(block.stop), x.size, force.size)
    if not 0 <= start < stop:
        raise ValueError(f'block {getattr(block, "index", "?")}: empty sample range [{block.start}, {block.stop})')
    amplitude, mean, frequency = float(block.amplitude), float(block.mean), float(block.frequency)
    if not (math.isfinite(amplitude) and amplitude > 0):
        raise ValueError(f'block {getattr(block, "index", "?")}: amplitude must be > 0, got {block.amplitude!r}')
    xs, fs = x[start:stop], force[start:stop]
    ok = np.isfinite(xs) & np.isfinite(fs)
    notes = []
    if not ok.all():
        notes.append(f'{int((~ok).sum())} samples with missing values left out')

    s = _velocity_sign(x, start, stop, frequency, dt)
    u = (xs - mean) / amplitude
    ellipse = s * np.sqrt(np.maximum(0.0, 1.0 - u * u))
    names = ['offset'] + [f'K{k}' for k in orders] + ['b']
    columns = [np.ones_like(xs)] + [xs ** k for k in orders] + [ellipse]
    design = np.column_stack(columns)[ok]
    y = fs[ok]
    n, p = design.shape
    if n <= p:
        raise ValueError(f'block {getattr(block, "index", "?")}: {n} samples for {p} parameters')
    noise = float(noise_level(fs[ok]) if noise is None else noise)
    coef, cov, rss, chi2_dof = _weighted_lstsq(design, y, noise, notes)
    dof = n - p
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = cov / np.outer(sig, sig)
    correlation = {f'{names[a]}-{names[c]}': float(corr[a, c]) for a in range(p) for c in range(a + 1, p)}

    row = {'frequency': frequency, 'amplitude': amplitude, 'mean': mean}
    row.update({name: float(v) for name, v in zip(names, coef, strict=True)})
    row.update({'sigma': {name: float(v) for name, v in zip(names, sig, strict=True)},
                'correlation': correlation, 'chi2_per_dof': float(chi2_dof),
                'residual_rms': float(math.sqrt(rss / n)), 'noise': noise, 'samples': int(n), 'dof': int(dof),
                'orders': orders, 'index': getattr(block, 'index', None),
                'recording': getattr(block, 'recording', ''), 'notes': notes})
    return row


def _weighted_lstsq(design, y, noise: float, notes: list) -> tuple:
    """(coefficients, covariance, residual sum of squares, chi2/dof) of y = design @ c for load-cell noise sigma
    `noise` [N]; the covariance is inflated by chi2/dof when that exceeds 1. Without a usable noise level the
    sigmas come from the residual scatter (noted).
    """
    n, p = design.shape
    # columns of very different size (x^3 ~ 1e-9 m^3): solve on unit-norm columns, scale back
    scale = np.linalg.norm(design, axis=0)
    scale[scale == 0] = 1.0
    scaled = design / scale
    coef_s, *_ = np.linalg.lstsq(scaled, y, rcond=None)
    residual = y - scaled @ coef_s
    rss = float(residual @ residual)
    dof = n - p
    if noise > 0 and math.isfinite(noise):
        chi2_dof = rss / noise ** 2 / dof
        variance = noise ** 2 * max(1.0, chi2_dof)
    else:
        chi2_dof = math.nan
        variance = rss / dof
        notes.append('no load-cell noise level: sigmas from the residual scatter, chi2/dof undefined')
    cov_s = variance * np.linalg.pinv(scaled.T @ scaled)
    return coef_s / scale, cov_s / np.outer(scale, scale), rss, chi2_dof


def fit_blocks(runs_blocks, orders=(1, 3)) -> list:
    """:func:`fit_block` for every block of every run: ``runs_blocks`` = [(RunData, [BlockResult, ...]), ...].

    Returns the per-block dicts in order; 'recording' is the block's recording name, else the run's name.
    """
    rows = []
    for run, blocks in runs_blocks:
        for block in blocks:
            row = fit_block(run.displacement, run.force, run.dt, block, orders=orders)
            if not row['recording']:
                row['recording'] = run.name
            rows.append(row)
    return rows


# ------------------------------------------------------------------------------------------------------ trend

def _distinct(values, rtol=0.02) -> int:
    """Number of distinct operating-point values, values within ``rtol`` (relative) of the previous one merged
    (a measured 2.001 Hz is the 2 Hz case).
    """
    v = np.sort(np.asarray(values, dtype=float))
    if v.size == 0:
        return 0
    count, last = 1, v[0]
    for value in v[1:]:
        if value - last > rtol * max(abs(value), abs(last)):
            count += 1
            last = value
    return count


def _design(f, a, f_degree, a_degree):
    return np.column_stack([f ** i * a ** j for i in range(f_degree + 1) for j in range(a_degree + 1)])


def fit_trend(rows, name, f_degree=3, a_degree=2) -> dict:
    """Weighted least squares of the per-block values rows[i][name] onto a table c[i][j] (seed 004 Eq. 7-12).

    Parameters
    ----------
    rows : list of dict
        :func:`fit_block` results ('frequency' [Hz], 'amplitude' [m], name, 'sigma'[name]); weights 1 / sigma^2.
    name : str
        The coefficient, e.g. 'K1', 'K3', 'b'.
    f_degree, a_degree : int
        Highest powers of frequency [Hz] and amplitude [m]; each is lowered (with a note) to one less than the
        number of distinct values in the data, and further while the design is rank-deficient.

    Returns
    -------
    dict
        'name'; 'coefficients' c[i][j] (nested list, SI, for :func:`rubber_rig.models.trend.trend_value`); 'sigma'
        (same shape, scaled by sqrt(max(1, chi2/dof))); 'chi2_per_dof' (nan without degrees of freedom);
        'residuals' (value / trend - 1 per row); 'normalised_residuals' ((value - trend) / sigma per row);
        'f_degree', 'a_degree'; 'notes'; 'warnings' (chi2/dof > 2, no degrees of freedom, unusable rows).
    """
    if int(f_degree) < 0 or int(a_degree) < 0:
        raise ValueError(f'degrees must be >= 0, got f_degree={f_degree!r}, a_degree={a_degree!r}')
    f_degree, a_degree = int(f_degree), int(a_degree)
    notes, warnings = [], []
    f = np.array([float(r['frequency']) for r in rows], dtype=float)
    a = np.array([float(r['amplitude']) for r in rows], dtype=float)
    y = np.array([float(r.get(name, math.nan)) for r in rows], dtype=float)
    sigma = np.array([float(r.get('sigma', {}).get(name, math.nan)) for r in rows], dtype=float)
    use = np.isfinite(f) & np.isfinite(a) & np.isfinite(y) & np.isfinite(sigma) & (sigma > 0)
    if not use.all():
        warnings.append(f'{int((~use).sum())} of {len(rows)} rows without a finite {name} and sigma > 0 left out')
    if not use.any():
        raise ValueError(f'no row has a finite {name} with a sigma > 0')
    fu, au, yu, su = f[use], a[use], y[use], sigma[use]

    # unit-size variables for the solve; c[i][j] = c'[i][j] / (f_s^i a_s^j)
    f_s = float(np.max(np.abs(fu))) or 1.0
    a_s = float(np.max(np.abs(au))) or 1.0
    design, f_degree, a_degree = _solvable_design(fu / f_s, au / a_s, su, f_degree, a_degree, notes)
    p = design.shape[1]
    rhs = yu / su
    coef_s, *_ = np.linalg.lstsq(design, rhs, rcond=None)
    res = rhs - design @ coef_s
    dof = yu.size - p
    chi2 = float(res @ res)
    if dof > 0:
        chi2_dof = chi2 / dof
        if chi2_dof > 2:
            warnings.append(f'chi2/dof = {chi2_dof:.3g} > 2: the trend does not describe the per-block {name} within '
                            'their uncertainties (sigmas scaled up accordingly)')
    else:
        chi2_dof = math.nan
        warnings.append(f'no degrees of freedom left ({yu.size} values, {p} coefficients): the trend interpolates '
                        f'the per-block {name}, nothing checks it')
    cov_s = np.linalg.inv(design.T @ design) * max(1.0, chi2_dof if dof > 0 else 1.0)
    powers = np.array([f_s ** i * a_s ** j for i in range(f_degree + 1) for j in range(a_degree + 1)])
    coef = coef_s / powers
    sig = np.sqrt(np.maximum(np.diag(cov_s), 0.0)) / powers
    shape = (f_degree + 1, a_degree + 1)

    fitted = np.full(y.shape, math.nan)
    fitted[use] = _design(fu, au, f_degree, a_degree) @ coef
    with np.errstate(invalid='ignore', divide='ignore'):
        relative = y / fitted - 1.0
        normalised = (y - fitted) / sigma
    return {'name': name, 'coefficients': coef.reshape(shape).tolist(), 'sigma': sig.reshape(shape).tolist(),
            'chi2_per_dof': float(chi2_dof), 'residuals': relative.tolist(),
            'normalised_residuals': normalised.tolist(), 'f_degree': f_degree, 'a_degree': a_degree,
            'notes': notes, 'warnings': warnings}


# ----------------------------------------------------------------------------------------------------- report


def _solvable_design(fu, au, su, f_degree: int, a_degree: int, notes: list) -> tuple:
    """(weighted design matrix, f degree, A degree) with the degrees lowered (each with a note) to what the
    data can determine: one less than the distinct values, then while the design is rank-deficient.
    """
    n_f, n_a = _distinct(fu), _distinct(au)
    if f_degree > n_f - 1:
        notes.append(f'{n_f} distinct frequencies: frequency degree lowered from {f_degree} to {n_f - 1}')
        f_degree = n_f - 1
    if a_degree > n_a - 1:
        notes.append(f'{n_a} distinct amplitudes: amplitude degree lowered from {a_degree} to {n_a - 1}')
        a_degree = n_a - 1
    while True:
        design = _design(fu, au, f_degree, a_degree) / su[:, None]
        p = design.shape[1]
        if np.linalg.matrix_rank(design) == p and p <= su.size:
            return design, f_degree, a_degree
        # e.g. operating points on a diagonal instead of a grid: drop the higher of the two degrees
        old = (f_degree, a_degree)
        if f_degree >= a_degree and f_degree > 0:
            f_degree -= 1
        else:
            a_degree -= 1
        notes.append(f'design rank-deficient for degrees (f {old[0]}, A {old[1]}): lowered to (f {f_degree}, '
                     f'A {a_degree})')


def _paper_unit(name):
    """(factor, unit): value [SI] * factor = value in the paper's units; K_k [N/m^k] -> kN/mm^k, b, offset -> kN."""
    if name.startswith('K') and name[1:].isdigit():
        k = int(name[1:])
        return _KN / _MM ** k, 'kN/mm' if k == 1 else f'kN/mm^{k}'
    return _KN, 'kN'


def _pm(value, sigma, width=16):
    text = f'{value:.4g} +- {sigma:.2g}' if math.isfinite(sigma) else f'{value:.4g}'
    return text.rjust(width)


def per_block_report(rows, trends) -> str:
    """Plain-text table of the per-block fits and the trends in the paper's units.

    rows: :func:`fit_block` results; trends: :func:`fit_trend` results (a list, or a dict name -> result).
    Per block: f [Hz], A [mm], x0 [mm], each K_k [kN/mm^k], b [kN] with +- 1 sigma, chi2/dof and the K1-K3
    correlation. Per trend: c[i][j] in the paper's unit per Hz^i mm^j, with +- 1 sigma, chi2/dof, notes, warnings.
    """
    if isinstance(trends, dict) and 'coefficients' not in trends:
        trends = list(trends.values())
    elif isinstance(trends, dict):
        trends = [trends]
    names = []
    for r in rows:
        for k in r.get('orders', ()):
            if f'K{k}' not in names:
                names.append(f'K{k}')
    names = sorted(names, key=lambda s: int(s[1:])) + ['b']
    head = ['f [Hz]'.rjust(8), 'A [mm]'.rjust(8), 'x0 [mm]'.rjust(8)]
    head += [f'{n} [{_paper_unit(n)[1]}]'.rjust(20) for n in names]
    head += ['chi2/dof'.rjust(9), 'r(K1,K3)'.rjust(9)]
    lines = ['Per-block fits (seed 004 Eq. 6, +- 1 sigma)', ' '.join(head)]
    for r in rows:
        cells = [f'{r["frequency"]:8.3f}', f'{r["amplitude"] * _MM:8.4f}', f'{r["mean"] * _MM:8.4f}']
        for n in names:
            factor = _paper_unit(n)[0]
            if n in r:
                cells.append(_pm(r[n] * factor, r['sigma'][n] * factor, 20))
            else:
                cells.append('-'.rjust(20))
        cells.append(f'{r["chi2_per_dof"]:9.3g}')
        corr = r.get('correlation', {}).get('K1-K3')
        cells.append(f'{corr:9.4f}' if corr is not None else '-'.rjust(9))
        lines.append(' '.join(cells))
    for t in trends:
        factor, unit = _paper_unit(t['name'])
        lines += ['', f'Trend of {t["name"]}: c[i][j] [{unit} / (Hz^i mm^j)], value = sum c[i][j] f^i A^j '
                  f'(f degree {t["f_degree"]}, A degree {t["a_degree"]}, chi2/dof {t["chi2_per_dof"]:.3g})']
        lines.append('      ' + ' '.join(f'A^{j}'.rjust(22) for j in range(t['a_degree'] + 1)))
        for i, (crow, srow) in enumerate(zip(t['coefficients'], t['sigma'], strict=True)):
            cells = [_pm(c * factor / _MM ** j, s * factor / _MM ** j, 22)
                     for j, (c, s) in enumerate(zip(crow, srow, strict=True))]
            lines.append(f'f^{i}'.ljust(6) + ' '.join(cells))
        lines += [f'  note: {m}' for m in t.get('notes', [])]
        lines += [f'  warning: {m}' for m in t.get('warnings', [])]
    return '\n'.join(lines) + '\n'
