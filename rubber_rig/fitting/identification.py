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

"""From recordings to identified models: any model file, load-cell calibration, verdict and model ranking.

    runs -> load-cell calibration (delay, gain) -> blocks -> per temperature: harmonic global search
         -> time-domain refinement (optionally with the load-cell delay as a parameter) -> uncertainty
         -> per-block quality -> warnings (`verdict`)

`fit_model` identifies one model, `compare_models` several on the same data and ranks them by AIC and BIC
(chi^2 in units of the measured noise, so both count the data the same way for every candidate).
"""
from __future__ import annotations

import math

import numpy as np

from rubber_rig.models.modelfile import resolve_model

from .blocks import split_blocks
from .calibration import calibrate
from .data import with_temperature
from .group_fit import fit_group

METHODS = ('harmonic', 'time')
AIC_TIE = 2.0     # models within this many AIC units of the best are equally supported (Burnham & Anderson)


def _temp_key(t):
    return None if t is None else round(float(t) * 2.0) / 2.0


def quasi_static_windows(run) -> list:
    """Sample ranges (start, stop) of the run's triangle blocks (block index + recorded program)."""
    if run.block_index is None or not run.program_blocks:
        return []
    bi = np.asarray(run.block_index)
    change = np.flatnonzero(np.diff(bi) != 0) + 1
    bounds = np.concatenate([[0], change, [bi.size]])
    out = []
    for s, e in zip(bounds[:-1], bounds[1:], strict=True):
        k = int(bi[s])
        if 0 <= k < len(run.program_blocks) and run.program_blocks[k].get('waveform') == 'triangle' and e - s > 10:
            out.append((int(s), int(e)))
    return out


def split_runs(runs, settle_cycles=3, min_cycles=2):
    """{temperature key: [(run, blocks, quasi-static windows)]} and messages."""
    groups, messages = {}, []
    for run in runs:
        messages.extend(run.messages)
        if not run.usable():
            messages.append(f'{run.name}: no displacement or no force channel; not fitted')
            continue
        rep = split_blocks(run.displacement, run.force, run.dt, block_index=run.block_index,
                           program_blocks=run.program_blocks, settle_cycles=settle_cycles,
                           min_cycles=min_cycles, recording=run.name)
        messages.extend(rep.messages)
        if rep.blocks:
            groups.setdefault(_temp_key(run.temperature), []).append((run, rep.blocks, quasi_static_windows(run)))
    return groups, messages


def fit_model(runs, model='zener_berg', method='time', load_cell_delay=None, load_cell_gain=None,
              estimate_delay=False, settle_cycles=3, min_cycles=2, seed=0, w_k=100.0, w_c=1.0,
              progress=None, load_cell_gain_u=None, load_cell_delay_u=None, displacement_gain_u=None,
              temperature_u=None) -> tuple:
    """Identify ``model`` (model file, named model, parameter set or ModelSpec) from ``runs`` (RunData), one
    fit per temperature. Returns (fits, messages).

    The load cell's calibration (delay, gain and their standard uncertainties) is declared: given here, else
    the recordings' rig configuration. It is applied, never fitted away: the delay the data would prefer is a
    diagnostic (``load_cell['delay_check']``, a warning when it disagrees with the declared one).
    ``estimate_delay`` makes the delay a fit parameter instead (never below zero in total), for a load cell
    whose timing nobody measured; the fit then warns whenever the estimate is not zero. Likewise the
    displacement transducer's gain uncertainty and the temperature sensor's (``displacement_gain_u``,
    ``temperature_u``; the displacement gain itself comes from the rig configuration).
    """
    if method not in METHODS:
        raise ValueError(f'unknown fit method {method!r} (use one of {", ".join(METHODS)})')
    spec = resolve_model(model)
    if not spec.free():
        raise ValueError(f'model {spec.name or model!r}: every parameter is fixed; nothing to fit')
    calibrated, cals = [], {}
    for run in runs:
        if run.usable():
            run, cal = calibrate(run, load_cell_delay, load_cell_gain, load_cell_gain_u, load_cell_delay_u,
                                 displacement_gain_u=displacement_gain_u, temperature_u=temperature_u)
            # the channel's uncertainty includes the sensor's, declared only now (fitting.temperature)
            run = with_temperature(run, sensor_u=cal.get('temperature_u'))
            cals[run.name] = cal
        calibrated.append(run)
    groups, messages = split_runs(calibrated, settle_cycles, min_cycles)
    if not groups:
        raise ValueError('no usable blocks in any recording: ' + '; '.join(messages))
    fits = []
    order = sorted(groups.items(), key=lambda kv: (kv[0] is None, kv[0] or 0))
    for n, (temp, items) in enumerate(order):
        def stage(frac, what, n=n, temp=temp):
            if progress is not None:
                progress((n + frac) / len(order), f'{_label(temp)}: {what}')
        try:
            fit = fit_group(spec, items, temp, method, estimate_delay, w_k, w_c, seed, progress=stage,
                            calibration={run.name: cals[run.name] for run, _, _ in items})
        except ValueError as exc:
            messages.append(f'{_label(temp)}: not fitted: {exc}')
            continue
        fits.append(fit)
    if progress is not None:
        progress(1.0, 'done')
    if not fits:
        raise ValueError('nothing could be fitted: ' + '; '.join(messages))
    return fits, messages


def compare_models(fits_by_model: dict) -> list:
    """Rank candidate models fitted to the same data: per temperature, rows sorted by BIC with delta BIC /
    delta AIC to the best, BIC (Schwarz) and Akaike weights, and a sentence saying what the data support.

    The selected model is the lowest BIC. BIC is consistent: with the true model among the candidates it
    is chosen with a probability that goes to 1 as the data grow, which is what identifying a specimen's
    physics asks for. AIC aims at prediction and keeps an unneeded nested parameter in about 16 % of data
    sets (P(chi2_1 > 2)); its choice is reported beside it (the simplest model within ``AIC_TIE`` of the
    lowest AIC, as models that close are equally supported) and the sentence says when the two disagree.
    """
    temps = {}
    for name, fits in fits_by_model.items():
        for f in fits:
            temps.setdefault(f.temperature, []).append((name, f))
    out = []
    for temp, rows in temps.items():
        rows.sort(key=lambda nf: nf[1].bic)
        best_aic, best_bic = min(f.aic for _, f in rows), rows[0][1].bic
        table = [{'model': name, 'n_params': f.n_params, 'chi2_per_dof': f.chi2_per_dof, 'aic': f.aic, 'bic': f.bic,
                  'delta_aic': f.aic - best_aic, 'delta_bic': f.bic - best_bic, 'warnings': len(f.warnings)}
                 for name, f in rows]
        for key, weight in (('delta_aic', 'akaike_weight'), ('delta_bic', 'bic_weight')):
            w = np.exp(-0.5 * np.array([r[key] for r in table]))
            for r, wi in zip(table, w / w.sum(), strict=True):
                r[weight] = float(wi)
        selected = table[0]['model']
        tied = [r for r in table if r['delta_aic'] <= AIC_TIE]
        by_aic = min(tied, key=lambda r: (r['n_params'], r['delta_aic']))['model']
        second = table[1]['delta_bic'] if len(table) > 1 else math.inf
        # Kass & Raftery's scale for Bayes factors, 2 ln B ~ delta BIC
        strength = ('decisively' if second > 10 else 'strongly' if second > 6 else 'positively' if second > 2
                    else 'only weakly')
        if by_aic == selected:
            aic_text = 'AIC agrees'
        else:
            sel, alt = (next(r for r in table if r['model'] == m) for m in (selected, by_aic))
            aic_text = f'AIC prefers {by_aic} by {sel["delta_aic"] - alt["delta_aic"]:.1f} units' + (
                f' (see whether the parameters {by_aic} adds are consistent with zero)'
                if alt['n_params'] > sel['n_params'] else '')
        verdict_text = (f'{_label(temp)}: the data support {selected} {strength} '
                        f'(next best delta BIC {second:.1f}); {aic_text}')
        out.append({'temperature': temp, 'ranking': table, 'selected': selected, 'selected_bic': selected,
                    'selected_aic': by_aic, 'verdict': verdict_text})
    return out


def _label(temp):
    return 'unknown temperature' if temp is None else f'{temp:g} degC'
