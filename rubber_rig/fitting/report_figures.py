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


"""The report's figures (matplotlib, Agg backend; mm, kN, kN/mm and kN s/m like the papers): loops, K_dyn and C_eq,
R_K and R_E, traces and per-block errors; what each shows: report.py's module docstring.
"""
from __future__ import annotations

import math

import numpy as np

from rubber_rig.models import steady_state_properties

from .report_events import mark_events
from .report_model import model_band

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
        pr = steady_state_properties(p, fgrid, a, kdyn='eq24')    # R_K as seed 000 Eq. 30 prints it
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
