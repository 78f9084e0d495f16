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

"""Reports that show misfit: PNG files plus one self-contained HTML page, in the style of seed 000's figures.

The model is any composite model (`ReportModel`: a model file written by `rubber-rig fit`, with its
uncertainties and fit record, a hand-written model file, or a seed-000 parameter set). Its force is the
model run over the measured displacement exactly as the fit runs it (`timefit.run_input`: low-pass and
Berg reversal deadband; `ParallelModel` of the model's elements), compared at t - d with d the load-cell
delay of the fit (calibration + estimate); the measured force is divided by the calibration gain.

Figures (matplotlib, Agg backend; mm, kN, kN/mm and kN s/m like the papers):
  loops.png      hysteresis loops per block, measured on top of the model, and under each loop the
                 residual F_model - F_measured (block offset removed) over the cycle phase, with the
                 load-cell noise as a +-2 sigma band (seed 000 Fig. 5/6)
  kdyn_ceq.png   K_dyn and C_eq vs frequency per amplitude: measured with 1-sigma error bars from the
                 load-cell noise, the model's first harmonic as lines with a band from the parameter
                 uncertainty, the model run over the measured displacement as crosses (Fig. 4)
  ratios.png     R_K and R_E vs frequency per amplitude (Eq. 30, Fig. 7), fractional Zener + Berg only
  traces.png     displacement, measured and model force, and the force residual over time
  errors.png     per-block relative errors of K_dyn and C_eq (Eq. 28) with the measurement's 1 sigma

Measurement sigmas: `blocks.harmonic_sigma`, sigma(K_dyn) = sigma_F sqrt(2/N) / A and sigma(C_eq) =
sigma_F sqrt(2/N) / (omega A), N the analysed samples of the block and sigma_F = `blocks.noise_level` of the
(calibrated) force.
"""
from __future__ import annotations

import base64
import html
import io
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from rubber_rig.models import ZenerBergParams, steady_state_properties
from rubber_rig.models.composite import ParallelModel
from rubber_rig.models.modelfile import ModelSpec, load_model_file, spec_from_params
from rubber_rig.units import to_si

from .blocks import harmonic_sigma, noise_level
from .fitwarnings import warning_text
from .identification import calibrate, corrected_force
from .metrics import window_properties
from .modelfit import DELAY, Z95, paper_unit
from .paramfile import PARAM_NAMES
from .report_events import events_html, fig_cycles, mark_events
from .timefit import run_input

_NO_MODEL = defaultdict(lambda: math.nan)
FIGURES = ('loops', 'kdyn_ceq', 'ratios', 'traces', 'cycles', 'errors')
BAND_SAMPLES = 50          # parameter sets drawn for the model band of kdyn_ceq.png
_RESULT_KEYS = ('sigma', 'interval_95', 'relative_sigma', 'budget', 'interval_method')


# ---- the model reported on ---------------------------------------------------------------------------

@dataclass
class ReportModel:
    """A model to report on: its spec, the uncertainty of its parameters and the record of its fit.

    ``results``: parameter name (``ModelSpec.parameters`` names; ``load_cell_delay`` too) -> {sigma,
    interval_95, relative_sigma} in SI. ``fit``: the model file's ``fit`` mapping (chi2_per_dof,
    warnings, notes, load_cell, recordings, method), None when the model has no fit record.
    """

    spec: ModelSpec
    results: dict = field(default_factory=dict)
    fit: dict | None = None
    source: str = ''
    known_delay: float = 0.0     # the load-cell calibration delay [s] (`calibrated_run` sets it)

    @property
    def load_cell(self) -> dict:
        lc = (self.fit or {}).get('load_cell')
        return lc if isinstance(lc, dict) else {}

    @property
    def estimated_delay(self) -> float:
        """The load-cell delay [s] the fit estimated beyond the calibration (0 when it did not)."""
        d = self.load_cell.get('delay_estimated')
        return float(d) if d is not None and math.isfinite(float(d)) else 0.0

    @property
    def delay(self) -> float:
        """The whole load-cell delay [s] the model is compared with: calibration + estimate, as in the fit."""
        return self.known_delay + self.estimated_delay

    @property
    def is_zener_berg(self) -> bool:
        """Seed 000's model: one fractional Zener and one Berg element."""
        return sorted(e.type for e in self.spec.elements) == ['berg', 'fractional_zener']

    def zener_berg_params(self) -> ZenerBergParams:
        v = {}
        for e in self.spec.elements:
            v.update(e.values)
        return ZenerBergParams(**{k: float(v[k]) for k in PARAM_NAMES})


def _si(raw, dimension):
    if isinstance(raw, (list, tuple)):
        return [_si(r, dimension) for r in raw]
    try:
        return to_si(raw, dimension)
    except ValueError:
        return math.nan if isinstance(raw, str) or raw is None else float(raw)    # .inf / .nan as written


def read_model_file(path) -> ReportModel:
    """A model file (``elements:``) with the sigma / interval_95 / relative_sigma beside each element's
    values and the ``fit:`` record that `rubber-rig fit` writes (both optional).
    """
    spec = load_model_file(path)
    data = yaml.safe_load(Path(str(path)).expanduser().read_text(encoding='utf-8'))
    names = {(i, p): n for n, i, p in spec.parameters()}
    results = {}
    for i, entry in enumerate(data.get('elements') or []):
        if not isinstance(entry, dict):
            continue
        for key in _RESULT_KEYS:
            got = entry.get(key)
            if not isinstance(got, dict):
                continue
            for p, raw in got.items():
                name = names.get((i, p))
                if name is None:
                    continue
                if key == 'budget':        # {contribution: standard uncertainty in SI, or None: undeclared}
                    results.setdefault(name, {})[key] = {c: None if v is None else float(v)
                                                         for c, v in (raw or {}).items()}
                    continue
                if key == 'interval_method':
                    results.setdefault(name, {})[key] = str(raw)
                    continue
                dim = 'number' if key == 'relative_sigma' else spec.param_spec(name).dimension
                results.setdefault(name, {})[key] = _si(raw, dim)
    fit = spec.meta.get('fit')
    fit = dict(fit) if isinstance(fit, dict) else None
    lc = (fit or {}).get('load_cell') or {}
    if lc.get('delay_estimated') is not None and lc.get('delay_sigma') is not None:
        d, s = float(lc['delay_estimated']), float(lc['delay_sigma'])
        # the fit's own interval (+-t sigma over its blocks); files written before it stored one: +-1.96 sigma
        interval = lc.get('delay_interval_95') or [d - Z95 * s, d + Z95 * s]
        results[DELAY] = {'sigma': s, 'interval_95': [float(v) for v in interval],
                          'relative_sigma': s / abs(d) if d else math.inf}
    return ReportModel(spec, results, fit, str(path))


def model_from_fit(fit, source: str = '') -> ReportModel:
    """The `ReportModel` of a `modelfit.ModelFit` (what `rubber-rig fit` would write)."""
    record = {'recordings': list(fit.runs), 'method': fit.method, 'chi2_per_dof': fit.chi2_per_dof,
              'warnings': list(fit.warnings), 'notes': list(fit.notes), 'load_cell': dict(fit.load_cell)}
    results = {k: dict(v) for k, v in fit.uncertainty.items()}
    return ReportModel(fit.model, results, record, source)


def parameter_set_model(values: dict, name: str = '', source: str = '', temperature=None) -> ReportModel:
    """A seed-000 parameter set (the layout of rubber_rig/models/data/swing_arm_joint.yaml) as a model."""
    spec = spec_from_params(ZenerBergParams(**{k: float(values[k]) for k in PARAM_NAMES}), name)
    if temperature is not None:
        spec.meta['temperature'] = float(temperature)
    return ReportModel(spec, {}, None, source)


def calibrated_run(run, model: ReportModel | None):
    """(run, {delay, gain, source}): ``run`` with the measured force divided by the calibration gain the
    model's fit applied (without a fit record, the recording's rig configuration, as `rubber-rig fit` uses by
    default); the calibration delay goes to the model (``model.known_delay``: the model is compared at
    t - delay, as in the fit, instead of interpolating the measured force, which would filter its noise).
    ``run`` itself when there is nothing to correct.
    """
    lc = model.load_cell if model is not None else {}
    if 'delay' in lc or 'gain' in lc:
        out, info = calibrate(run, float(lc.get('delay') or 0.0), float(lc.get('gain') or 1.0))
        info['source'] = f'fit record ({lc.get("calibration_source", "?")})'
    else:
        out, info = calibrate(run)
    if model is not None:
        model.known_delay = info['delay']
    return out, info


def model_force(model: ReportModel, run, blocks) -> np.ndarray:
    """Force [N] over samples [0, end) of the model run over the measured displacement as the fit runs it
    (`timefit.run_input`), compared at t - d for the load-cell delay d the fit estimated.
    """
    _, x, h = run_input(run, blocks)
    f = ParallelModel(model.spec.build_elements(run.dt, h), run.dt, model.spec.name, model.spec).run(x)
    return corrected_force(f, run.dt, -model.delay, 1.0) if model.delay else f


def block_quality(model: ReportModel | None, blocks, run, force, sigma_f) -> list:
    """Per block: measured K_dyn, C_eq with their 1-sigma from the load-cell noise, the model's (first
    harmonic at the block's frequency, amplitude and mean; and run over the measured displacement) and the
    relative errors (seed 000 Eq. 28).
    """
    analytic = None
    f = np.array([b.frequency for b in blocks])
    if model is not None:
        try:
            k = model.spec.first_harmonic(f, np.array([b.amplitude for b in blocks]),
                                          np.array([b.mean for b in blocks]))
            analytic = np.asarray(k) * np.exp(-2j * np.pi * f * model.delay)
        except ValueError:      # operating-point elements have no single first harmonic
            pass
    rows = []
    for i, b in enumerate(blocks):
        w = 2 * np.pi * b.frequency
        sk, sc = harmonic_sigma(sigma_f, b.stop - b.start, b.amplitude, b.frequency)
        row = {'recording': b.recording, 'block': b.index, 'frequency': b.frequency, 'amplitude': b.amplitude,
               'mean': b.mean, 'cycles': b.cycles,
               'measured': {'k_dyn': b.k_dyn, 'c_eq': b.c_eq, 'loss_angle': b.loss_angle, 'energy': b.energy,
                            'damping': b.damping, 'sigma_k': float(sk), 'sigma_c': float(sc)}}
        if analytic is not None:
            kd, ce = float(abs(analytic[i])), float(analytic[i].imag / w)
            row['analytic'] = {'k_dyn': kd, 'c_eq': ce, 'e_k': kd / b.k_dyn - 1, 'e_c': ce / b.c_eq - 1}
        if force is not None:
            hp = window_properties(run.displacement, force, run.dt, b.start, b.stop, b.frequency)
            row['simulated'] = {'k_dyn': hp['k_dyn'], 'c_eq': hp['c_eq'],
                                'e_k': hp['k_dyn'] / b.k_dyn - 1, 'e_c': hp['c_eq'] / b.c_eq - 1}
        rows.append(row)
    return rows


def model_band(model: ReportModel, frequency, amplitude, mean, n=BAND_SAMPLES, seed=0):
    """(K_dyn 16/84 %, C_eq 16/84 %, sets used) of the model's first harmonic over ``frequency`` for ``n``
    parameter sets drawn from independent normals with the reported sigmas (sets that break a parameter's
    limits are dropped); None when no parameter has a sigma.
    """
    rng = np.random.default_rng(seed)
    spec, res = model.spec, model.results
    values = spec.values()
    drawn = {name: rng.normal(values[name], res[name]['sigma'], n) for name, _, _ in spec.free()
             if math.isfinite(res.get(name, {}).get('sigma', math.nan)) and res[name]['sigma'] > 0}
    if not drawn:
        return None
    ok = np.ones(n, bool)
    full = {name: drawn.get(name, np.full(n, float(v))) for name, v in values.items()}
    by_param = {(i, p): name for name, i, p in spec.parameters()}
    for name, i, _ in spec.parameters():
        ps = spec.param_spec(name)
        v = full[name]
        ok &= np.isfinite(v)
        if not ps.signed:
            ok &= v > 0
        if ps.upper is not None:
            ok &= v <= ps.upper
        if ps.above and (i, ps.above) in by_param:
            ok &= v >= full[by_param[(i, ps.above)]]
    if ok.sum() < 3:
        return None
    d = np.full(n, model.delay)
    ds = res.get(DELAY, {}).get('sigma')
    if model.delay and ds is not None and math.isfinite(ds):
        d = rng.normal(model.delay, ds, n)
    f = np.asarray(frequency, float)
    w = 2 * np.pi * f
    with np.errstate(all='ignore'):
        k = spec.first_harmonic(f, amplitude, mean, {k: v[ok][:, None] for k, v in drawn.items()})
        k = np.asarray(k) * np.exp(-1j * w * d[ok][:, None])
        kd = np.nanpercentile(np.abs(k), [16, 84], axis=0)
        ce = np.nanpercentile(k.imag / w, [16, 84], axis=0)
    return kd, ce, int(ok.sum())


# ---- figures -----------------------------------------------------------------------------------------

def _plt():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def _amp_groups(items, amplitude=lambda b: b):
    """Items grouped by nominal (or rounded measured) amplitude [m] of their block, sorted."""
    groups = {}
    for it in items:
        b = amplitude(it)
        a = b.nominal_amplitude or float(f'{b.amplitude:.2g}')
        groups.setdefault(a, []).append(it)
    return dict(sorted(groups.items()))


def _force_unit(largest):
    return (1.0, 'N') if largest < 1000.0 else (1e-3, 'kN')


def _phase(x, frequency, dt, start):
    """Phase [deg] of each sample of x within its cycle: x ~ mean + A sin(phase)."""
    t = (start + np.arange(x.size)) * dt
    w = 2 * np.pi * frequency
    a, c, _ = np.linalg.lstsq(np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)]), x, rcond=None)[0]
    return np.degrees(w * t + math.atan2(c, a)) % 360.0


def _residuals(blocks, run, force):
    """Per block: (phase [deg], F_model - F_measured with the block's mean removed [N]) over its analysed cycles."""
    out = []
    for b in blocks:
        e = force[b.start:b.stop] - run.force[b.start:b.stop]
        out.append((_phase(run.displacement[b.start:b.stop], b.frequency, run.dt, b.start), e - e.mean()))
    return out


def fig_loops(blocks, run, force, sigma_f, plt):
    n = len(blocks)
    ncol = min(6, n)
    nrow = int(np.ceil(n / ncol))
    res = _residuals(blocks, run, force) if force is not None else None
    per = 2 if res else 1
    ratios = [2.3, 1.1] * nrow if res else [2.3] * nrow
    fig = plt.figure(figsize=(2.7 * ncol, sum(ratios) + 0.8))
    gs = fig.add_gridspec(len(ratios), ncol, height_ratios=ratios)
    if res:
        scale, unit = _force_unit(max(max(float(np.max(np.abs(e))) for _, e in res), 2 * sigma_f))
    for k, b in enumerate(blocks):
        r, c = divmod(k, ncol)
        ax = fig.add_subplot(gs[per * r, c])
        sl = slice(b.start, b.stop + 1)
        x = run.displacement[sl] * 1e3
        if force is not None:
            ax.plot(x, force[sl] * 1e-3, color='C3', lw=1.8, alpha=0.55, zorder=2, label='model')
        ax.plot(x, run.force[sl] * 1e-3, color='C0', lw=0.7, zorder=3, label='measured')
        ax.set_title(f'{b.frequency:.3g} Hz, {b.amplitude * 1e3:.3g} mm', fontsize=8)
        ax.tick_params(labelsize=7)
        if c == 0:
            ax.set_ylabel('force [kN]', fontsize=8)
        ax.set_xlabel('displacement [mm]', fontsize=7, labelpad=1)
        if k == 0:
            ax.legend(fontsize=7, loc='upper left')
        if res:
            rax = fig.add_subplot(gs[per * r + 1, c])
            phase, e = res[k]
            step = max(1, e.size // 1500)      # keep the panel readable and the PNG light
            phase, e = phase[::step], e[::step]
            rax.axhspan(-2 * sigma_f * scale, 2 * sigma_f * scale, color='0.85', lw=0, label='+-2 sigma noise')
            rax.plot(phase, e * scale, '.', ms=1.2, color='C3', label='model - measured')
            for y in (-2 * sigma_f * scale, 0.0, 2 * sigma_f * scale):
                rax.axhline(y, color='k', lw=0.5, ls='-' if y == 0 else '--', zorder=3)
            rax.set_xlim(0, 360)
            rax.set_xticks([0, 90, 180, 270, 360])
            rax.tick_params(labelsize=7)
            rax.set_xlabel('cycle phase [deg]', fontsize=7, labelpad=1)
            if c == 0:
                rax.set_ylabel(f'residual [{unit}]', fontsize=8)
            if k == 0:
                rax.legend(fontsize=6, loc='lower left', markerscale=4)
    title = 'Hysteresis loops, steady cycles: measured (blue) on the model (red) (cf. seed 000 Fig. 5/6)'
    if res:
        title += (f'\nunder each loop: F_model - F_measured (block offset removed) over the cycle phase '
                  f'(90 deg: largest displacement); grey: +-2 sigma load-cell noise ({sigma_f:.3g} N)')
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def fig_kdyn_ceq(blocks, model, quality, sigma_f, plt):
    fig, (ak, ac) = plt.subplots(1, 2, figsize=(12, 4.8))
    fmin = min(b.frequency for b in blocks)
    fmax = max(b.frequency for b in blocks)
    fgrid = np.geomspace(fmin * 0.8, fmax * 1.2, 160)
    wgrid = 2 * np.pi * fgrid
    band_used = None
    for i, (a, rows) in enumerate(_amp_groups(list(zip(blocks, quality, strict=True)), lambda r: r[0]).items()):
        col = f'C{i}'
        bl = [b for b, _ in rows]
        f = np.array([b.frequency for b in bl])
        m = [q['measured'] for _, q in rows]
        ak.errorbar(f, [b.k_dyn * 1e-6 for b in bl], yerr=[q['sigma_k'] * 1e-6 for q in m], fmt='o', ms=4,
                    color=col, capsize=3, label=f'measured {a * 1e3:g} mm')
        ac.errorbar(f, [b.c_eq * 1e-3 for b in bl], yerr=[q['sigma_c'] * 1e-3 for q in m], fmt='o', ms=4,
                    color=col, capsize=3, label=f'measured {a * 1e3:g} mm')
        sim = [q.get('simulated') for _, q in rows]
        if all(sim):
            ak.plot(f, [s['k_dyn'] * 1e-6 for s in sim], 'x', color=col, ms=6)
            ac.plot(f, [s['c_eq'] * 1e-3 for s in sim], 'x', color=col, ms=6)
        if model is None or 'analytic' not in rows[0][1]:
            continue
        amp = float(np.mean([b.amplitude for b in bl]))
        mean = float(np.mean([b.mean for b in bl]))
        k = np.asarray(model.spec.first_harmonic(fgrid, amp, mean)) * np.exp(-1j * wgrid * model.delay)
        ak.plot(fgrid, np.abs(k) * 1e-6, '-', color=col, lw=1.2, label=f'model {a * 1e3:g} mm')
        ac.plot(fgrid, k.imag / wgrid * 1e-3, '-', color=col, lw=1.2, label=f'model {a * 1e3:g} mm')
        band = model_band(model, fgrid, amp, mean)
        if band is not None:
            kd, ce, band_used = band
            ak.fill_between(fgrid, kd[0] * 1e-6, kd[1] * 1e-6, color=col, alpha=0.2, lw=0)
            ac.fill_between(fgrid, ce[0] * 1e-3, ce[1] * 1e-3, color=col, alpha=0.2, lw=0)
    ak.plot([], [], 'x', color='0.3', label='model run over measured x')
    ak.set_ylabel('dynamic stiffness K_dyn [kN/mm]')
    ac.set_ylabel('equivalent damping C_eq [kN s/m]')
    ac.set_yscale('log')
    for ax in (ak, ac):
        ax.set_xlabel('frequency [Hz]')
        ax.set_xscale('log')
        ax.grid(alpha=0.3, which='both')
        ax.legend(fontsize=7)
    note = (f'shaded: model +-1 sigma (16-84 % of {band_used} parameter sets drawn from independent normals)'
            if band_used else 'no parameter uncertainty in the model: no band')
    fig.suptitle('Dynamic properties vs frequency (cf. seed 000 Fig. 4); error bars: 1 sigma from the load-cell '
                 f'noise ({sigma_f:.3g} N)\nlines: model first harmonic; {note}', fontsize=10)
    fig.tight_layout()
    return fig, band_used


def fig_ratios(blocks, model, plt):
    fig, (ak, ae) = plt.subplots(1, 2, figsize=(11, 4.2))
    fgrid = np.geomspace(min(b.frequency for b in blocks) * 0.8, max(b.frequency for b in blocks) * 1.2, 120)
    p = model.zener_berg_params()
    for i, a in enumerate(_amp_groups(blocks)):
        pr = steady_state_properties(p, fgrid, a)
        ak.plot(fgrid, pr['r_k'], color=f'C{i}', label=f'{a * 1e3:g} mm')
        ae.plot(fgrid, pr['r_e'], color=f'C{i}', label=f'{a * 1e3:g} mm')
    for ax, name in ((ak, 'R_K = K_dv / K_df'), (ae, 'R_E = E_v / E_f')):
        ax.axhline(1.0, color='0.5', lw=0.8, ls='--')
        ax.set_xlabel('frequency [Hz]')
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle('Viscous vs friction contributions (seed 000 Eq. 30, cf. Fig. 7)')
    fig.tight_layout()
    return fig


def fig_traces(run, force, blocks, sigma_f, plt):
    end = max(b.stop for b in blocks) + 1
    t = np.arange(end) * run.dt
    step = max(1, end // 20000)          # keep the PNG light: at most ~20k points per line
    sl = slice(0, end, step)
    fig, axes = plt.subplots(3, 1, figsize=(11, 7), sharex=True)
    axes[0].plot(t[sl], run.displacement[:end][sl] * 1e3, lw=0.6)
    axes[0].set_ylabel('displacement [mm]')
    if force is not None:
        axes[1].plot(t[sl], force[:end][sl] * 1e-3, lw=1.2, color='C3', alpha=0.6, label='model')
    axes[1].plot(t[sl], run.force[:end][sl] * 1e-3, lw=0.5, color='C0', label='measured')
    if force is not None:
        e = force[:end] - run.force[:end]
        scale, unit = _force_unit(max(float(np.max(np.abs(e))), 2 * sigma_f))
        axes[2].axhspan(-2 * sigma_f * scale, 2 * sigma_f * scale, color='0.8', lw=0, label='+-2 sigma noise')
        axes[2].plot(t[sl], e[sl] * scale, lw=0.5, color='C3', label='model - measured')
        for y in (-2 * sigma_f * scale, 2 * sigma_f * scale):
            axes[2].axhline(y, color='k', lw=0.7, ls='--', zorder=3)
        axes[2].set_ylabel(f'residual [{unit}]')
        axes[2].legend(fontsize=8, loc='upper right')
    axes[1].set_ylabel('force [kN]')
    axes[1].legend(fontsize=8, loc='upper right')
    axes[2].set_xlabel('time [s]')
    for ax in axes:
        for b in blocks:
            ax.axvspan(b.start * run.dt, b.stop * run.dt, color='C0', alpha=0.06, lw=0)
        ax.grid(alpha=0.3)
    mark_events(axes, getattr(run, 'events', []), run.dt)
    axes[0].set_title('Time traces (shaded: analysed steady cycles of each block; dashed: detector events)')
    fig.tight_layout()
    return fig


def fig_errors(quality, plt):
    fig, ax = plt.subplots(figsize=(11, 3.8))
    idx = np.arange(len(quality))
    kind = 'simulated' if 'simulated' in quality[0] else 'analytic'
    ek = [100 * q[kind]['e_k'] for q in quality]
    ec = [100 * q[kind]['e_c'] for q in quality]
    sk = [100 * q['measured']['sigma_k'] / q['measured']['k_dyn'] for q in quality]
    sc = [100 * q['measured']['sigma_c'] / q['measured']['c_eq'] for q in quality]
    ax.bar(idx - 0.2, ek, 0.4, yerr=sk, capsize=2, label='K_dyn')
    ax.bar(idx + 0.2, ec, 0.4, yerr=sc, capsize=2, label='C_eq')
    ax.set_xticks(idx, [f'{q["frequency"]:.2g}Hz\n{q["amplitude"] * 1e3:.2g}mm' for q in quality], fontsize=6)
    ax.set_ylabel('model - measured [%]')
    ax.axhline(0, color='k', lw=0.6)
    ax.grid(alpha=0.3, axis='y')
    ax.legend(fontsize=8)
    what = 'run over the measured displacement' if kind == 'simulated' else 'first harmonic'
    ax.set_title(f'Relative errors per block (seed 000 Eq. 28; model {what}; error bars: 1 sigma of the '
                 'measurement from the load-cell noise)', fontsize=9)
    fig.tight_layout()
    return fig


# ---- report ------------------------------------------------------------------------------------------

def make_report(run, blocks, model: ReportModel | None, outdir, title=None, messages=(), calibration=None):
    """Write the figures and report.html into `outdir`; return {name: path} of the files written.

    ``run`` carries the measured force the model is compared with (calibrated: `calibrated_run`, whose
    info dict is ``calibration``); ``blocks`` are its analysed blocks.
    """
    plt = _plt()
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    if not blocks:
        raise ValueError(f'{run.name}: no usable block to report on')
    end = min(max(b.stop for b in blocks) + 1, run.force.size)
    sigma_f = noise_level(run.force[:end])
    force = model_force(model, run, blocks) if model is not None else None
    quality = block_quality(model, blocks, run, force, sigma_f)
    figs = {'loops': fig_loops(blocks, run, force, sigma_f, plt)}
    figs['kdyn_ceq'], band_used = fig_kdyn_ceq(blocks, model, quality, sigma_f, plt)
    skipped = {}
    if model is not None and model.is_zener_berg:
        figs['ratios'] = fig_ratios(blocks, model, plt)
    else:
        skipped['ratios'] = ('R_K and R_E (seed 000 Eq. 30, Fig. 7) split the fractional Zener from the Berg '
                             'friction; this model is not fractional Zener + Berg, so the figure is left out.')
    figs['traces'] = fig_traces(run, force, blocks, sigma_f, plt)
    cycles = fig_cycles(run, plt)
    if cycles is not None:
        figs['cycles'] = cycles
    if model is not None:
        figs['errors'] = fig_errors(quality, plt)
    files, images = {}, {}
    for name, fig in figs.items():
        buf = io.BytesIO()
        fig.savefig(buf, format='png', dpi=110)
        plt.close(fig)
        data = buf.getvalue()
        path = outdir / f'{name}.png'
        path.write_bytes(data)
        files[name] = path
        images[name] = base64.b64encode(data).decode('ascii')
    stats = _fit_on_run(blocks, run, force, sigma_f)
    page = _html(run, blocks, model, quality, images, title, messages, sigma_f, stats, band_used, skipped,
                 calibration)
    files['html'] = outdir / 'report.html'
    files['html'].write_text(page, encoding='utf-8')
    return files


def _fit_on_run(blocks, run, force, sigma_f):
    """Mean of r^2 over the analysed samples, r = residual (block offset removed) / sigma_F; None w/o model."""
    if force is None or not sigma_f:
        return None
    e = np.concatenate([r for _, r in _residuals(blocks, run, force)])
    return float(np.mean((e / sigma_f) ** 2)), e.size


# ---- HTML --------------------------------------------------------------------------------------------

_STYLE = ('<style>body{font-family:sans-serif;max-width:1250px;margin:2em auto;color:#222}'
          'table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #ccc;padding:3px 8px;'
          'text-align:right}th{background:#f3f3f3}td.l,th.l{text-align:left}img{max-width:100%}'
          '.box{padding:.6em 1em;margin:1em 0;border-radius:4px}'
          '.warnings{background:#fff3cd;border:2px solid #d39e00}.ok{background:#e7f5e9;border:1px solid #5a9e68}'
          '.nofit{background:#f3f3f3;border:1px solid #bbb}.caption{color:#555;font-size:13px}</style>')


def _g(v, fmt='.5g'):
    return '&ndash;' if v is None or not math.isfinite(v) else format(v, fmt)


def budget_text(result: dict, value: float) -> str:
    """'type A 0.12, load cell gain 0.29, load cell delay undeclared' (% of the value) for a result with a
    ``budget``; '' without one (a model file written before budgets, a fixed parameter).
    """
    budget = result.get('budget') or {}
    if not budget or not value:
        return ''
    label = {'type_a': 'Type A', 'load_cell_gain': 'load-cell gain', 'load_cell_delay': 'load-cell delay',
             'displacement_gain': 'displacement gain'}
    return ', '.join(f'{label.get(k, k)} ' + ('undeclared' if v is None else f'{_g(100 * v / abs(value), ".2g")}')
                     for k, v in budget.items())


def _param_table(model: ReportModel):
    spec, res = model.spec, model.results
    labels = spec.labels()
    rows = [(name, labels[i], spec.elements[i].values[p], p in spec.elements[i].fixed)
            for name, i, p in spec.parameters()]
    if DELAY in res:
        rows.append((DELAY, 'load cell', model.estimated_delay, False))
    parts = ['<table class="params"><tr><th class="l">parameter</th><th class="l">element</th><th>value</th>'
             '<th>&plusmn;1 sigma</th><th>&plusmn;1 sigma [%]</th><th>95 % interval</th><th class="l">unit</th>'
             '<th class="l">budget, 1 sigma [% of value]</th></tr>']
    for name, label, value, fixed in rows:
        f, unit = paper_unit(spec, name)
        r = res.get(name, {})
        s, iv = r.get('sigma'), r.get('interval_95')
        if not iv and s is not None and not fixed:
            iv = [value - Z95 * s, value + Z95 * s]
        rel = r.get('relative_sigma', s / abs(value) if s is not None and value else None)
        sig = 'fixed' if fixed else ('&ndash;' if s is None else f'&plusmn;{_g(s * f, ".3g")}')
        rel_s = '' if fixed or rel is None or name == DELAY else _g(100 * rel, '.3g')   # delay: near 0
        ivs = '' if not iv else f'[{_g(iv[0] * f)}, {_g(iv[1] * f)}]'
        parts.append(f'<tr><td class="l">{html.escape(name)}</td><td class="l">{html.escape(label)}</td>'
                     f'<td>{_g(value * f)}</td><td>{sig}</td><td>{rel_s}</td><td>{ivs}</td>'
                     f'<td class="l">{html.escape(unit)}</td><td class="l">{budget_text(r, value)}</td></tr>')
    parts.append('</table>')
    return parts


def _fit_box(model: ReportModel):
    esc = html.escape
    fit = model.fit
    if fit is None:
        return ['<div class="box nofit">This model has no fit record (no chi2/dof, no warnings): it was not '
                'written by <code>rubber-rig fit</code>. Judge it by the residuals and the error bars below.</div>']
    chi = fit.get('chi2_per_dof')
    lc = model.load_cell
    parts = [f'<p>Fit: chi2/dof = <b>{_g(chi, ".3g") if chi is not None else "&ndash;"}</b> (residuals in units '
             f'of the load-cell noise; near 1 when the model describes the data to their noise)'
             + (f', method {esc(str(fit["method"]))}' if fit.get('method') else '')
             + (f', recordings {esc(", ".join(map(str, fit["recordings"])))}' if fit.get('recordings') else '')
             + '.</p>']
    if lc.get('delay_estimated') is not None:
        parts.append(f'<p>Load-cell delay estimated by the fit: {_g(1e3 * model.estimated_delay, ".4g")} ms '
                     f'(&plusmn;{_g(1e3 * float(lc.get("delay_sigma") or math.nan), ".3g")} ms); the model force '
                     'is compared at t - delay.</p>')
    warnings = fit.get('warnings') or []
    if warnings:
        parts.append('<div class="box warnings"><b>Warnings</b><ul>'
                     + ''.join(f'<li>{esc(warning_text(w))}</li>' for w in warnings) + '</ul></div>')
    else:
        parts.append('<div class="box ok"><b>No warnings</b>: the fit found the model describes its data to '
                     'their noise level.</div>')
    notes = fit.get('notes') or []
    if notes:
        parts.append('<p>Fit notes:</p><ul>' + ''.join(f'<li>{esc(str(n))}</li>' for n in notes) + '</ul>')
    return parts


def _html(run, blocks, model, quality, images, title, messages, sigma_f, stats, band_used, skipped, calibration):
    esc = html.escape
    title = title or f'rubber_rig report: {run.name}'
    parts = [f'<!DOCTYPE html><html><head><meta charset="utf-8"><title>{esc(title)}</title>', _STYLE,
             '</head><body>', f'<h1>{esc(title)}</h1>',
             f'<p>Recording <b>{esc(run.name)}</b>: {run.displacement.size} samples at {1 / run.dt:g} Hz, '
             f'temperature {esc(str(run.temperature))} &deg;C, {len(blocks)} analysed blocks, load-cell noise '
             f'sigma_F = {sigma_f:.3g} N.</p>']
    if calibration and (calibration.get('delay') or calibration.get('gain', 1.0) != 1.0):
        parts.append(f'<p>Load-cell calibration applied to the measured force ({esc(str(calibration["source"]))}): '
                     f'delay {1e3 * calibration["delay"]:.4g} ms, gain {calibration["gain"]:.6g}.</p>')
    if model is not None:
        spec = model.spec
        temp = spec.meta.get('temperature')
        parts.append(f'<h2>Model: {esc(spec.name or "model")}</h2>'
                     f'<p>Elements in parallel: {esc(" + ".join(e.type for e in spec.elements))}'
                     + (f'; identified at {temp:g} &deg;C' if isinstance(temp, (int, float)) else '')
                     + (f'. Source: {esc(model.source)}' if model.source else '') + '.</p>')
        parts += _fit_box(model)
        parts.append('<h3>Parameters (papers\' units)</h3>')
        parts += _param_table(model)
        if not model.results:
            parts.append('<p>No uncertainties in this model (no sigma beside the values).</p>')
        if stats is not None:
            msr, n = stats
            parts.append(f'<p>On this recording: mean (residual / sigma_F)<sup>2</sup> = <b>{msr:.3g}</b> over '
                         f'{n} analysed samples (offset per block removed; no parameter fitted here, so near 1 '
                         'means the model reproduces this recording to its noise).</p>')
    if quality:
        has_a = quality[0].get('analytic') is not None        # a report without a model has neither
        has_s = quality[0].get('simulated') is not None
        head = ['f [Hz]', 'x0 [mm]', 'cycles', 'K_dyn [kN/mm]', '&plusmn;1 sigma']
        head += ['model run'] * has_s + ['model 1st harm.'] * has_a + ['e_K run [%]'] * has_s
        head += ['e_K 1st harm. [%]'] * has_a + ['C_eq [kN s/m]', '&plusmn;1 sigma'] + ['model run'] * has_s
        head += ['model 1st harm.'] * has_a + ['e_C run [%]'] * has_s + ['e_C 1st harm. [%]'] * has_a
        head += ['loss angle [deg]', 'E [J]']
        parts.append('<h2>Blocks</h2><table class="blocks"><tr>' + ''.join(f'<th>{h}</th>' for h in head) + '</tr>')
        for q in quality:
            # without a model the columns are absent; the NaN rows only keep the expressions below evaluable
            m, s, a = q['measured'], q.get('simulated') or _NO_MODEL, q.get('analytic') or _NO_MODEL
            cells = [f'{q["frequency"]:.3g}', f'{q["amplitude"] * 1e3:.3g}', str(q['cycles']),
                     f'{m["k_dyn"] * 1e-6:.4g}', f'{m["sigma_k"] * 1e-6:.2g}']
            cells += [f'{s["k_dyn"] * 1e-6:.4g}'] * has_s + [f'{a["k_dyn"] * 1e-6:.4g}'] * has_a
            cells += [f'{100 * s["e_k"]:.2f}'] * has_s + [f'{100 * a["e_k"]:.2f}'] * has_a
            cells += [f'{m["c_eq"] * 1e-3:.4g}', f'{m["sigma_c"] * 1e-3:.2g}']
            cells += [f'{s["c_eq"] * 1e-3:.4g}'] * has_s + [f'{a["c_eq"] * 1e-3:.4g}'] * has_a
            cells += [f'{100 * s["e_c"]:.2f}'] * has_s + [f'{100 * a["e_c"]:.2f}'] * has_a
            cells += [f'{np.degrees(m["loss_angle"]):.2f}', f'{m["energy"]:.4g}']
            parts.append('<tr>' + ''.join(f'<td>{c}</td>' for c in cells) + '</tr>')
        parts.append('</table>')
        for kind, what in (('simulated', 'run over the measured displacement'), ('analytic', 'first harmonic')):
            if quality[0].get(kind) is not None:
                ek = max(abs(q[kind]['e_k']) for q in quality)
                ec = max(abs(q[kind]['e_c']) for q in quality)
                parts.append(f'<p>Max |error|, model {what}: K_dyn {100 * ek:.2f} %, C_eq {100 * ec:.2f} %.</p>')
    parts += events_html(getattr(run, 'events', []))
    if messages:
        parts.append('<h2>Notes</h2><ul>' + ''.join(f'<li>{esc(m)}</li>' for m in messages) + '</ul>')
    band = (f'The shaded bands are the model\'s +-1 sigma from its parameter uncertainty: {band_used} parameter '
            'sets drawn from independent normals with the reported sigmas, 16-84 % at each frequency. The file '
            'carries no correlations; ignoring them usually widens the band (parameters the data pin together, '
            'like x2 and f_fmax, move independently here).'
            if band_used else 'The model carries no parameter uncertainty: no band.')
    captions = {
        'loops': ('Hysteresis loops and residuals (cf. seed 000 Fig. 5/6)',
                  'Measured loops (blue) drawn on top of the model (red). Under each loop the residual F_model - '
                  'F_measured (offset per block removed) over the cycle phase (90 deg = largest displacement); '
                  f'grey band: +-2 sigma_F load-cell noise ({sigma_f:.3g} N). Residuals that leave the band in a '
                  'pattern repeated every cycle are misfit, not noise.'),
        'kdyn_ceq': ('K_dyn and C_eq vs frequency with error bars (cf. seed 000 Fig. 4)',
                     'Points: measured, with 1-sigma error bars from the load-cell noise (sigma_F sqrt(2/N) / A for '
                     'K_dyn, / (omega A) for C_eq, N analysed samples). Lines: the model\'s first harmonic at each '
                     'amplitude; crosses: the model run over the measured displacement. ' + band),
        'ratios': ('R_K and R_E (seed 000 Eq. 30, Fig. 7)', ''),
        'traces': ('Time traces and residual', 'Residual F_model - F_measured over the whole recording; grey: '
                                               '+-2 sigma_F.'),
        'cycles': ('K_dyn and C_eq cycle by cycle (online)',
                   'Every cycle the element model measured while the test ran (recorded CycleMetrics): measured '
                   'points and the model\'s value for the same cycle. A durability test\'s stiffness curve; dashed '
                   'lines: detector events (grey record, orange warn, red hold, black end).'),
        'errors': ('Relative errors per block (Eq. 28)', 'Error bars: 1 sigma of the measured K_dyn and C_eq.'),
    }
    for name in FIGURES:
        head, text = captions[name]
        if name in images:
            parts.append(f'<h2>{esc(head)}</h2><img alt="{name}" src="data:image/png;base64,{images[name]}">'
                         + (f'<p class="caption">{esc(text)}</p>' if text else ''))
        elif name in skipped:
            parts.append(f'<h2>{esc(head)}</h2><p class="caption">{esc(skipped[name])}</p>')
    parts.append('</body></html>')
    return '\n'.join(parts)
