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

"""Reports that look like seed 000's figures: PNG files plus one self-contained HTML page.

Figures (matplotlib, Agg backend; mm, kN, kN/mm and kN s/m like the papers):
  loops.png      hysteresis loops measured vs model, one panel per block (seed 000 Fig. 5/6)
  kdyn_ceq.png   K_dyn and C_eq vs frequency per amplitude, measured points, model lines (Fig. 4)
  ratios.png     R_K and R_E vs frequency per amplitude (Eq. 30, Fig. 7)
  traces.png     displacement, measured and model force, and the force residual over time
  errors.png     per-block relative errors of K_dyn and C_eq (Eq. 28)
The model force is the model run over the measured displacement (as `timefit` does); the model lines
of Fig. 4 are the first-harmonic closed form (`properties`) and R_K, R_E come from
`rubber_rig.models.steady_state_properties` (seed 000 Eq. 30 as the paper defines them).
"""
from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import numpy as np

from rubber_rig.models import ZenerBergParams, steady_state_properties

from .identify import PARAM_NAMES
from .pipeline import block_quality
from .properties import measured_style_properties
from .timefit import model_force as run_model

FIGURES = ('loops', 'kdyn_ceq', 'ratios', 'traces', 'errors')
PAPER = {'k0': (1e-6, 'kN/mm'), 'k_inf': (1e-6, 'kN/mm'), 'tau': (1.0, 's'), 'alpha': (1.0, '-'),
         'x2': (1e3, 'mm'), 'f_fmax': (1e-3, 'kN')}


def _plt():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def _amp_groups(blocks):
    """Blocks grouped by nominal (or rounded measured) amplitude [m], sorted."""
    groups = {}
    for b in blocks:
        a = b.nominal_amplitude or float(f'{b.amplitude:.2g}')
        groups.setdefault(a, []).append(b)
    return dict(sorted(groups.items()))


def fig_loops(blocks, run, model_force, plt):
    n = len(blocks)
    ncol = min(6, n)
    nrow = int(np.ceil(n / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(2.6 * ncol, 2.3 * nrow), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax, b in zip(axes.flat, blocks, strict=False):
        sl = slice(b.start, b.stop + 1)
        x = run.displacement[sl] * 1e3
        ax.plot(x, run.force[sl] * 1e-3, color='0.55', lw=0.8, label='measured')
        if model_force is not None:
            ax.plot(x, model_force[sl] * 1e-3, color='C3', lw=1.0, label='model')
        ax.set_title(f'{b.frequency:.3g} Hz, {b.amplitude * 1e3:.3g} mm', fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7, loc='upper left')
    fig.supxlabel('displacement [mm]')
    fig.supylabel('force [kN]')
    fig.suptitle('Hysteresis loops, steady cycles: measured vs model (cf. seed 000 Fig. 5/6)')
    fig.tight_layout()
    return fig


def fig_kdyn_ceq(blocks, params, plt):
    fig, (ak, ac) = plt.subplots(1, 2, figsize=(11, 4.2))
    groups = _amp_groups(blocks)
    fmin = min(b.frequency for b in blocks)
    fmax = max(b.frequency for b in blocks)
    fgrid = np.geomspace(fmin * 0.8, fmax * 1.2, 200)
    for i, (a, bl) in enumerate(groups.items()):
        col = f'C{i}'
        f = np.array([b.frequency for b in bl])
        ak.plot(f, [b.k_dyn * 1e-6 for b in bl], 'o', color=col, label=f'measured {a * 1e3:g} mm')
        ac.plot(f, [b.c_eq * 1e-3 for b in bl], 'o', color=col, label=f'measured {a * 1e3:g} mm')
        if params is not None:
            amp = float(np.mean([b.amplitude for b in bl]))
            pr = measured_style_properties(*(params[k] for k in PARAM_NAMES), fgrid, amp)
            ak.plot(fgrid, pr['k_dyn'] * 1e-6, '-', color=col, label=f'model {a * 1e3:g} mm')
            ac.plot(fgrid, pr['c_eq'] * 1e-3, '-', color=col, label=f'model {a * 1e3:g} mm')
    ak.set_ylabel('dynamic stiffness K_dyn [kN/mm]')
    ac.set_ylabel('equivalent damping C_eq [kN s/m]')
    ac.set_yscale('log')
    for ax in (ak, ac):
        ax.set_xlabel('frequency [Hz]')
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle('Dynamic properties vs frequency (cf. seed 000 Fig. 4)')
    fig.tight_layout()
    return fig


def fig_ratios(blocks, params, plt):
    fig, (ak, ae) = plt.subplots(1, 2, figsize=(11, 4.2))
    groups = _amp_groups(blocks)
    fgrid = np.geomspace(min(b.frequency for b in blocks) * 0.8, max(b.frequency for b in blocks) * 1.2, 120)
    p = ZenerBergParams(**{k: float(params[k]) for k in PARAM_NAMES})
    for i, a in enumerate(groups):
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


def fig_traces(run, model_force, blocks, plt):
    end = max(b.stop for b in blocks) + 1
    t = np.arange(end) * run.dt
    step = max(1, end // 20000)          # keep the PNG light: at most ~20k points per line
    sl = slice(0, end, step)
    fig, axes = plt.subplots(3, 1, figsize=(11, 7), sharex=True)
    axes[0].plot(t[sl], run.displacement[:end][sl] * 1e3, lw=0.6)
    axes[0].set_ylabel('displacement [mm]')
    axes[1].plot(t[sl], run.force[:end][sl] * 1e-3, lw=0.6, color='0.5', label='measured')
    if model_force is not None:
        axes[1].plot(t[sl], model_force[:end][sl] * 1e-3, lw=0.6, color='C3', label='model')
        axes[2].plot(t[sl], (run.force[:end] - model_force[:end])[sl] * 1e-3, lw=0.5, color='C2')
    axes[1].set_ylabel('force [kN]')
    axes[1].legend(fontsize=8, loc='upper right')
    axes[2].set_ylabel('residual [kN]')
    axes[2].set_xlabel('time [s]')
    for ax in axes:
        for b in blocks:
            ax.axvspan(b.start * run.dt, b.stop * run.dt, color='C0', alpha=0.06, lw=0)
        ax.grid(alpha=0.3)
    axes[0].set_title('Time traces (shaded: analysed steady cycles of each block)')
    fig.tight_layout()
    return fig


def fig_errors(quality, plt):
    fig, ax = plt.subplots(figsize=(11, 3.8))
    n = len(quality)
    idx = np.arange(n)
    kind = 'simulated' if quality and 'simulated' in quality[0] else 'analytic'
    ek = [100 * q[kind]['e_k'] for q in quality]
    ec = [100 * q[kind]['e_c'] for q in quality]
    ax.bar(idx - 0.2, ek, 0.4, label='K_dyn')
    ax.bar(idx + 0.2, ec, 0.4, label='C_eq')
    ax.set_xticks(idx, [f'{q["frequency"]:.2g}Hz\n{q["amplitude"] * 1e3:.2g}mm' for q in quality], fontsize=6)
    ax.set_ylabel('model - measured [%]')
    ax.axhline(0, color='k', lw=0.6)
    ax.grid(alpha=0.3, axis='y')
    ax.legend(fontsize=8)
    ax.set_title(f'Relative errors per block (seed 000 Eq. 28; model {kind})')
    fig.tight_layout()
    return fig


def make_report(run, blocks, params, outdir, quality=None, title=None, param_info=None, messages=()):
    """Write the figures and report.html into `outdir`; return {name: path} of the files written."""
    plt = _plt()
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    if not blocks:
        raise ValueError(f'{run.name}: no usable block to report on')
    model_force = None
    if params is not None:
        _, model_force = run_model(params, run, blocks)
    if quality is None and params is not None:
        quality = block_quality(params, blocks, {run.name: run}, forces={run.name: model_force})
    figs = {'loops': fig_loops(blocks, run, model_force, plt),
            'kdyn_ceq': fig_kdyn_ceq(blocks, params, plt)}
    if params is not None:
        figs['ratios'] = fig_ratios(blocks, params, plt)
    figs['traces'] = fig_traces(run, model_force, blocks, plt)
    if quality:
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
    page = _html(run, blocks, params, quality, images, title, param_info, messages)
    files['html'] = outdir / 'report.html'
    files['html'].write_text(page, encoding='utf-8')
    return files


def _html(run, blocks, params, quality, images, title, param_info, messages):
    esc = html.escape
    title = title or f'rubber_rig report: {run.name}'
    parts = [f'<!DOCTYPE html><html><head><meta charset="utf-8"><title>{esc(title)}</title>',
             '<style>body{font-family:sans-serif;max-width:1200px;margin:2em auto;color:#222}'
             'table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #ccc;padding:3px 8px;'
             'text-align:right}th{background:#f3f3f3}img{max-width:100%}</style></head><body>',
             f'<h1>{esc(title)}</h1>',
             f'<p>Recording <b>{esc(run.name)}</b>: {run.displacement.size} samples at {1 / run.dt:g} Hz, '
             f'temperature {esc(str(run.temperature))} &deg;C, {len(blocks)} analysed blocks.</p>']
    if params is not None:
        parts.append('<h2>Model parameters (seed 000, fractional Zener + Berg friction)</h2><table><tr>')
        parts += [f'<th>{n} [{PAPER[n][1]}]</th>' for n in PARAM_NAMES] + ['</tr><tr>']
        parts += [f'<td>{params[n] * PAPER[n][0]:.4g}</td>' for n in PARAM_NAMES] + ['</tr>']
        sig = (param_info or {}).get('relative_sigma')
        if sig:
            parts += ['<tr>'] + [f'<td>&plusmn;{100 * sig[n]:.2f} %</td>' for n in PARAM_NAMES] + ['</tr>']
        parts.append('</table>')
        if param_info and param_info.get('source'):
            parts.append(f'<p>Parameters: {esc(str(param_info["source"]))}</p>')
    if quality:
        kind = 'simulated' if 'simulated' in quality[0] else 'analytic'
        parts.append('<h2>Blocks</h2><table><tr><th>f [Hz]</th><th>x0 [mm]</th><th>cycles</th>'
                     '<th>K_dyn [kN/mm]</th><th>model</th><th>e_K [%]</th><th>loss angle [deg]</th>'
                     '<th>D</th><th>E [J]</th><th>C_eq [kN s/m]</th><th>model</th><th>e_C [%]</th></tr>')
        for q in quality:
            m, e = q['measured'], q[kind]
            parts.append(
                f'<tr><td>{q["frequency"]:.3g}</td><td>{q["amplitude"] * 1e3:.3g}</td><td>{q["cycles"]}</td>'
                f'<td>{m["k_dyn"] * 1e-6:.4g}</td><td>{e["k_dyn"] * 1e-6:.4g}</td><td>{100 * e["e_k"]:.2f}</td>'
                f'<td>{np.degrees(m["loss_angle"]):.2f}</td><td>{m["damping"]:.3f}</td><td>{m["energy"]:.4g}</td>'
                f'<td>{m["c_eq"] * 1e-3:.4g}</td><td>{e["c_eq"] * 1e-3:.4g}</td><td>{100 * e["e_c"]:.2f}</td></tr>')
        parts.append('</table>')
        ek = max(abs(q[kind]['e_k']) for q in quality)
        ec = max(abs(q[kind]['e_c']) for q in quality)
        parts.append(f'<p>Max |error|: K_dyn {100 * ek:.2f} %, C_eq {100 * ec:.2f} % '
                     f'(model {"run over the measured displacement" if kind == "simulated" else "closed form"}).</p>')
    if messages:
        parts.append('<h2>Notes</h2><ul>' + ''.join(f'<li>{esc(m)}</li>' for m in messages) + '</ul>')
    captions = {'loops': 'Hysteresis loops (cf. seed 000 Fig. 5/6)', 'kdyn_ceq': 'K_dyn and C_eq vs frequency (Fig. 4)',
                'ratios': 'R_K and R_E (Eq. 30, Fig. 7)', 'traces': 'Time traces and residual',
                'errors': 'Relative errors per block'}
    for name, b64 in images.items():
        parts.append(f'<h2>{esc(captions.get(name, name))}</h2>'
                     f'<img alt="{name}" src="data:image/png;base64,{b64}">')
    parts.append('</body></html>')
    return '\n'.join(parts)
