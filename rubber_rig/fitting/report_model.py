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


"""The model a report shows (`ReportModel`): read from a model file, a fit or a parameter set; its force over a
recording exactly as the fit runs it (`timefit.run_input`), its per-block quality against the measurement and the
band its parameter uncertainty spans. Used by the report (report.py) and its figures (report_figures.py).
"""
from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from rubber_rig.models import ZenerBergParams
from rubber_rig.models.composite import ParallelModel
from rubber_rig.models.modelfile import ModelSpec, load_model_file, spec_from_params
from rubber_rig.units import to_si

from .blocks import harmonic_sigma
from .calibration import calibrate, corrected_force
from .metrics import window_properties
from .misfit import misfit_record
from .modelfit import DELAY, Z95
from .paramfile import PARAM_NAMES
from .timefit import run_input

_NO_MODEL = defaultdict(lambda: math.nan)
BAND_SAMPLES = 50          # parameter sets drawn for the model band of kdyn_ceq.png
_RESULT_KEYS = ('sigma', 'interval_95', 'relative_sigma', 'budget', 'interval_method', 'interval_note')


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
              'misfit_test': misfit_record(fit.misfit),
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
