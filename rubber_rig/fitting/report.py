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
from pathlib import Path

import numpy as np

from .blocks import noise_level
from .fitwarnings import warning_text
from .modelfit import DELAY, Z95, paper_unit
from .report_events import events_html, fig_cycles
from .report_figures import _plt, _residuals, fig_errors, fig_kdyn_ceq, fig_loops, fig_ratios, fig_traces
from .report_model import _NO_MODEL, ReportModel, block_quality, model_force

FIGURES = ('loops', 'kdyn_ceq', 'ratios', 'traces', 'cycles', 'errors')


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
    if v is not None and math.isinf(v):       # an unbounded side of an interval (budget.interval_note)
        return '&infin;' if v > 0 else '-&infin;'
    return '&ndash;' if v is None or not math.isfinite(v) else format(v, fmt)


def budget_text(result: dict, value: float) -> str:
    """'type A 0.12, load cell gain 0.29, load cell delay undeclared' (% of the value) for a result with a
    ``budget``; '' without one (a model file written before budgets, a fixed parameter).
    """
    budget = result.get('budget') or {}
    if not budget or not value:
        return ''
    label = {'type_a': 'Type A', 'load_cell_gain': 'load-cell gain', 'load_cell_delay': 'load-cell delay',
             'displacement_gain': 'displacement gain', 'displacement_noise': 'displacement noise'}
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
        ivs = '' if not iv else f'[{_g(float(iv[0]) * f)}, {_g(float(iv[1]) * f)}]'
        parts.append(f'<tr><td class="l">{html.escape(name)}</td><td class="l">{html.escape(label)}</td>'
                     f'<td>{_g(value * f)}</td><td>{sig}</td><td>{rel_s}</td><td>{ivs}</td>'
                     f'<td class="l">{html.escape(unit)}</td><td class="l">{budget_text(r, value)}</td></tr>')
    parts.append('</table>')
    notes = [(name, res[name]['interval_note']) for name, *_ in rows if (res.get(name) or {}).get('interval_note')]
    if notes:
        parts.append('<ul>' + ''.join(f'<li>{html.escape(n)}: {html.escape(str(t))}</li>' for n, t in notes) + '</ul>')
    return parts


def _fit_box(model: ReportModel):
    esc = html.escape
    fit = model.fit
    if fit is None:
        return ['<div class="box nofit">This model has no fit record (no chi2/dof, no warnings): it was not '
                'written by <code>rubber-rig fit</code>. Judge it by the residuals and the error bars below.</div>']
    chi = fit.get('chi2_per_dof')
    lc = model.load_cell
    test = fit.get('misfit_test') or {}
    # the same figure and test as `rubber-rig fit` prints and its JSON states (misfit.misfit_sentence)
    verdict_text = (f'{esc(str(test["summary"]))} ({esc(str(test.get("test", "")))})' if test.get('summary') else
                    'residuals in units of the load-cell noise; near 1 when the model describes the data to their '
                    'noise; this model file records no misfit test')
    parts = [f'<p>Fit: chi2/dof = <b>{_g(chi, ".3g") if chi is not None else "&ndash;"}</b>: {verdict_text}'
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
        parts += _model_html(model, stats)
    if quality:
        parts += _blocks_html(quality)
    parts += events_html(getattr(run, 'events', []))
    if messages:
        parts.append('<h2>Notes</h2><ul>' + ''.join(f'<li>{esc(m)}</li>' for m in messages) + '</ul>')
    captions = _captions(sigma_f, band_used)
    for name in FIGURES:
        head, text = captions[name]
        if name in images:
            parts.append(f'<h2>{esc(head)}</h2><img alt="{name}" src="data:image/png;base64,{images[name]}">'
                         + (f'<p class="caption">{esc(text)}</p>' if text else ''))
        elif name in skipped:
            parts.append(f'<h2>{esc(head)}</h2><p class="caption">{esc(skipped[name])}</p>')
    parts.append('</body></html>')
    return '\n'.join(parts)


def _model_html(model, stats) -> list:
    """The model section: its elements, the fit box, the parameter table and how it reproduces the recording."""
    esc = html.escape
    spec = model.spec
    temp = spec.meta.get('temperature')
    parts = [f'<h2>Model: {esc(spec.name or "model")}</h2>'
             f'<p>Elements in parallel: {esc(" + ".join(e.type for e in spec.elements))}'
             + (f'; identified at {temp:g} &deg;C' if isinstance(temp, (int, float)) else '')
             + (f'. Source: {esc(model.source)}' if model.source else '') + '.</p>']
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
    return parts


def _blocks_html(quality) -> list:
    """The block table (measured, and the model run and first harmonic where there is a model) and its maxima."""
    has_a = quality[0].get('analytic') is not None        # a report without a model has neither
    has_s = quality[0].get('simulated') is not None
    head = ['f [Hz]', 'x0 [mm]', 'cycles', 'K_dyn [kN/mm]', '&plusmn;1 sigma']
    head += ['model run'] * has_s + ['model 1st harm.'] * has_a + ['e_K run [%]'] * has_s
    head += ['e_K 1st harm. [%]'] * has_a + ['C_eq [kN s/m]', '&plusmn;1 sigma'] + ['model run'] * has_s
    head += ['model 1st harm.'] * has_a + ['e_C run [%]'] * has_s + ['e_C 1st harm. [%]'] * has_a
    head += ['loss angle [deg]', 'E [J]']
    parts = ['<h2>Blocks</h2><table class="blocks"><tr>' + ''.join(f'<th>{h}</th>' for h in head) + '</tr>']
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
    return parts


def _captions(sigma_f: float, band_used) -> dict:
    """Figure name -> (heading, caption): what each figure shows and how to read it."""
    band = (f'The shaded bands are the model\'s +-1 sigma from its parameter uncertainty: {band_used} parameter '
            'sets drawn from independent normals with the reported sigmas, 16-84 % at each frequency. The file '
            'carries no correlations; ignoring them usually widens the band (parameters the data pin together, '
            'like x2 and f_fmax, move independently here).'
            if band_used else 'The model carries no parameter uncertainty: no band.')
    return {
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
