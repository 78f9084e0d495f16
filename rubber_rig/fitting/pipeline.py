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

"""From recordings to a parameter table per temperature, with fit quality per block.

    runs -> blocks (split_blocks) -> group by temperature -> harmonic fit (Eq. 29, DE + polish)
         -> optional time-domain refinement -> per-block quality -> table

Method 'harmonic' is seed 000's identification (Eq. 29 only). Method 'time' (default) starts from it
and refines on the raw loops (see `timefit`). Fit quality is reported two ways for every block:
`analytic` (first-harmonic closed form at the measured frequency and amplitude) and `simulated`
(the fitted model run over the measured displacement and evaluated by the same
`harmonic_properties` code as the measurement, i.e. exactly the way the data were produced).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

from .blocks import split_blocks
from .identify import PARAM_NAMES, Targets, fit_harmonic, objective, params_to_z
from .metrics import window_properties
from .properties import measured_style_properties
from .timefit import TimeDomainProblem, fit_time_domain, model_force

METHODS = ('harmonic', 'time')


@dataclass
class TemperatureFit:
    temperature: float | None
    runs: list
    blocks: list
    params: dict
    method: str
    objective: float
    uncertainty: dict
    stages: dict
    bounds: dict
    quality: list = field(default_factory=list)   # per block dicts
    timings: dict = field(default_factory=dict)
    messages: list = field(default_factory=list)
    true_params: dict | None = None
    eq29: float = float('nan')            # seed 000 Eq. 29 at the final parameters

    def max_errors(self, kind='simulated'):
        ek = [abs(q[kind]['e_k']) for q in self.quality if kind in q]
        ec = [abs(q[kind]['e_c']) for q in self.quality if kind in q]
        return (max(ek) if ek else float('nan')), (max(ec) if ec else float('nan'))

    def as_dict(self) -> dict:
        ek, ec = self.max_errors('analytic')
        sk, sc = self.max_errors('simulated')
        out = {
            'temperature': self.temperature, 'recordings': self.runs, 'method': self.method,
            'params': self.params, 'objective': self.objective, 'eq29': self.eq29, 'uncertainty': self.uncertainty,
            'stages': self.stages,
            'bounds': {k: list(v) for k, v in self.bounds.items()},
            'max_error': {'analytic': {'k_dyn': ek, 'c_eq': ec}, 'simulated': {'k_dyn': sk, 'c_eq': sc}},
            'blocks': self.quality, 'timings': self.timings, 'messages': self.messages,
        }
        if self.true_params:
            out['true_params'] = self.true_params
            out['param_errors'] = {k: self.params[k] / self.true_params[k] - 1.0 for k in PARAM_NAMES
                                   if k in self.true_params}
        return out


def _temp_key(t):
    return None if t is None else round(float(t) * 2.0) / 2.0


def block_quality(params, blocks, runs_by_name, simulate_blocks=True, forces=None):
    """Per-block measured vs model K_dyn and C_eq (relative errors as Eq. 28).

    ``forces``: optional {recording name: model force [N]} already computed by
    `timefit.model_force` for that recording's blocks (not simulated again).
    """
    t = Targets.from_blocks(blocks)
    pr = measured_style_properties(*(params[k] for k in PARAM_NAMES), t.frequency, t.amplitude)
    rows = []
    for i, b in enumerate(blocks):
        rows.append({
            'recording': b.recording, 'block': b.index, 'frequency': b.frequency, 'amplitude': b.amplitude,
            'cycles': b.cycles, 'measured': {'k_dyn': b.k_dyn, 'c_eq': b.c_eq, 'loss_angle': b.loss_angle,
                                             'damping': b.damping, 'energy': b.energy, 'mean': b.mean},
            'analytic': {'k_dyn': float(pr['k_dyn'][i]), 'c_eq': float(pr['c_eq'][i]),
                         'e_k': float(pr['k_dyn'][i] / b.k_dyn - 1), 'e_c': float(pr['c_eq'][i] / b.c_eq - 1),
                         'r_k': float(pr['r_k'][i]), 'r_e': float(pr['r_e'][i])},
        })
    if simulate_blocks:
        forces = forces or {}
        by_run = {}
        for i, b in enumerate(blocks):
            by_run.setdefault(b.recording, []).append(i)
        for name, idxs in by_run.items():
            run = runs_by_name[name]
            force = forces.get(name)
            if force is None:
                _, force = model_force(params, run, [blocks[i] for i in idxs])
            for i in idxs:
                b = blocks[i]
                hp = window_properties(run.displacement, force, run.dt, b.start, b.stop, b.frequency)
                rows[i]['simulated'] = {'k_dyn': hp['k_dyn'], 'c_eq': hp['c_eq'],
                                        'e_k': hp['k_dyn'] / b.k_dyn - 1, 'e_c': hp['c_eq'] / b.c_eq - 1}
    return rows


def fit_runs(runs, method='time', w_k=100.0, w_c=1.0, settle_cycles=3, min_cycles=2, seed=0,
             maxiter=400, popsize=20, progress=None, simulate_quality=True):
    """Fit every temperature present in `runs` (list of RunData). Returns (fits, messages)."""
    if method not in METHODS:
        raise ValueError(f'unknown fit method {method!r} (use one of {", ".join(METHODS)})')
    messages = []
    groups = {}
    split = {}
    for run in runs:
        messages.extend(run.messages)
        if not run.usable():
            continue
        rep = split_blocks(run.displacement, run.force, run.dt, block_index=run.block_index,
                           program_blocks=run.program_blocks, settle_cycles=settle_cycles,
                           min_cycles=min_cycles, recording=run.name)
        messages.extend(f'{run.name}: {m}' if not m.startswith(run.name) else m for m in rep.messages)
        if not rep.blocks:
            continue
        split[run.name] = rep.blocks
        groups.setdefault(_temp_key(run.temperature), []).append(run)
    if not groups:
        raise ValueError('no usable blocks in any recording: ' + '; '.join(messages))
    fits = []
    for n_group, (temp, group) in enumerate(sorted(groups.items(), key=lambda kv: (kv[0] is None, kv[0] or 0))):
        def stage_progress(frac, what, n_group=n_group, temp=temp):
            if progress is not None:
                progress((n_group + frac) / len(groups), f'{_label(temp)}: {what}')

        t0 = time.perf_counter()
        blocks = [b for run in group for b in split[run.name]]
        targets = Targets.from_blocks(blocks)
        try:
            h = fit_harmonic(targets, w_k=w_k, w_c=w_c, seed=seed, maxiter=maxiter, popsize=popsize,
                             progress=(lambda f, w: stage_progress(0.5 * f if method == 'time' else f, w)))
        except ValueError as exc:     # e.g. too few blocks at this temperature: fit the others
            messages.append(f'{_label(temp)} ({", ".join(run.name for run in group)}): not fitted: {exc}')
            continue
        result = h
        stages = dict(h.stages)
        timings = dict(h.timings)
        if method == 'time':
            problem = TimeDomainProblem([(run, split[run.name]) for run in group])
            td = fit_time_domain(problem, h.params, h.bounds,
                                 progress=lambda f, w: stage_progress(0.5 + 0.5 * f, w))
            stages.update(td.stages)
            timings.update(td.timings)
            result = td
            result.messages = h.messages + td.messages
        runs_by_name = {run.name: run for run in group}
        quality = block_quality(result.params, blocks, runs_by_name, simulate_blocks=simulate_quality)
        timings['total_s'] = time.perf_counter() - t0
        truth = next((run.true_params for run in group if run.true_params), None)
        fits.append(TemperatureFit(
            temperature=temp, runs=[run.name for run in group], blocks=blocks, params=result.params,
            method=method, objective=result.objective, uncertainty=result.uncertainty, stages=stages,
            bounds=h.bounds, quality=quality, timings=timings, messages=list(result.messages),
            true_params=truth, eq29=float(objective(params_to_z(result.params), targets, w_k, w_c))))
    if progress is not None:
        progress(1.0, 'done')
    if not fits:
        raise ValueError('nothing could be fitted: ' + '; '.join(messages))
    return fits, messages


def _label(temp):
    return 'unknown temperature' if temp is None else f'{temp:g} degC'
