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

"""Identify any composite model (a model file) from recordings, with an honest uncertainty.

    blocks (split_blocks) -> harmonic global search (first harmonics of the model, exact, see
    rubber_rig.models.catalogue; fitting.search) -> time-domain refinement on the loops -> uncertainty
    -> verdict

Search coordinates and the harmonic global search: `rubber_rig.fitting.search`.

Objectives.
* time: the model is run over the measured displacement (low-passed, Berg deadband at the noise, see
  `timefit.model_input`) and its force is compared with the measured force at up to
  ``points_per_block`` samples per block, in units of the load-cell noise sigma_F the recording shows
  (`noise.band_noise`: the blocks' excitation harmonics removed first), a force offset per block removed:
  r = (F_model - F_measured - offset) / sigma_F.
  With the right model these residuals are the sensor noise, so chi^2 / dof = sum r^2 / (m - n - blocks)
  is near 1 and anything above says the model misses something the data show.
* The load cell's delay d can be a parameter: the model force is compared at t - d (harmonic: K e^{-jwd}).

Uncertainty (1 sigma of each parameter). With J the Jacobian of r in the search coordinates:
* noise: (J^T J)^-1 inflated by max(1, chi^2/dof), the lack of fit (a misfit widens every interval);
* blocks: the jackknife over blocks, linearised (the cluster-robust covariance CR3): leaving block b out
  moves the estimate by d_b = (J^T J - J_b^T J_b)^-1 J_b^T r_b, and the covariance is
  (B-1)/B sum_b (d_b - mean d)(d_b - mean d)^T. It sees misfit that is systematic within a block (a model
  error, a wrong delay) even when chi^2 cannot tell it from noise, and, unlike the plain sandwich (CR1,
  (J^T J)^-1 [sum_b J_b^T r_b r_b^T J_b] (J^T J)^-1 B/(B-1)), it grows for parameters that a few blocks
  pin down: seed 003's fractional branch rests on the highest-frequency blocks, and CR1 understated its
  scatter by about 25 % (c1 inside its 95 % interval in 17 of 20 seeds; 19 of 20 with CR3);
and the reported sigma is the larger of the two, per parameter, carried to physical units through the
coordinates (delta method); 95 % intervals are +-t sigma, t from Student's t with B - 1 degrees of freedom
(2.08 for 22 blocks), as the block term is estimated from B blocks.
"""
from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import t as student_t

from rubber_rig.models.composite import ParallelModel
from rubber_rig.models.modelfile import ModelSpec
from rubber_rig.units import PAPER_UNITS

from .fitwarnings import warning_dict
from .misfit import misfit_sentence
from .noise import run_noise
from .search import DELAY, Coordinates
from .stopping import stall_stop
from .timefit import model_input, run_input

Z95 = 1.959964
ELEMENT_CACHE = 3      # element forces kept per item and element (a Jacobian's base run outlives its columns)


# ---- time-domain objective -------------------------------------------------------------------------

class TimeProblem:
    """Force residuals in units of the load-cell noise, over the analysed cycles of every block."""

    def __init__(self, spec: ModelSpec, runs_blocks, points_per_block=200, delays: dict | None = None,
                 noise: dict | None = None):
        """runs_blocks: [(RunData, [BlockResult])] or [(RunData, [BlockResult], [(start, stop)])]: the
        optional third item are sample ranges of quasi-static blocks (triangles) that join the residual
        like blocks (seed 000 Section 3 step 1, seed 001 Eq. 9: they pin the friction element down).
        ``delays``: recording name -> known load-cell delay [s]: the model is compared at t - delay.
        ``noise``: recording name -> noise.run_noise of it (computed here when not given).
        """
        self.spec = spec
        self.items = []
        self.base_delay = []       # known load-cell delay [s] per item
        self.block_rows = []       # slices of the residual vector, one per block or quasi-static window
        self.f_max = []            # highest block frequency per item [Hz] (the model input's low-pass)
        self.item_rows = []        # slice of the residual vector per item (recording)
        self.block_frequency = []  # per block_rows entry: the block's frequency [Hz], None for quasi-static windows
        self.noise_estimates = []  # per item: {'force', 'displacement'} noise.NoiseEstimate
        row = 0
        for item in runs_blocks:
            run, blocks = item[0], item[1]
            extra = list(item[2]) if len(item) > 2 else []
            if not blocks:
                continue
            estimate = (noise or {}).get(run.name) or run_noise(run, blocks)
            self.noise_estimates.append(estimate)
            end, x, h = run_input(run, blocks, max((s for _, s in extra), default=0), estimate['displacement'].sigma)
            sigma = max(estimate['force'].sigma, 1e-9 * float(np.max(np.abs(run.force[:end]))))
            windows, first_row = [], row
            self.block_frequency += [b.frequency for b in blocks] + [None] * len(extra)
            for start, stop in [(b.start, b.stop) for b in blocks] + [(a, min(s, end)) for a, s in extra]:
                step = max(1, (stop - start) // points_per_block)
                idx = np.arange(start, stop, step)
                windows.append(idx)
                self.block_rows.append(slice(row, row + idx.size))
                row += idx.size
            self.items.append((run, x, h, run.force[:end], windows, sigma))
            self.f_max.append(max(b.frequency for b in blocks))
            self.item_rows.append(slice(first_row, row))
            self.base_delay.append(float((delays or {}).get(run.name, 0.0)))
        self.m = row
        self._element_forces = OrderedDict()    # (item, element, its values) -> its force over the item [N]

    @property
    def noise(self) -> dict:
        return {run.name: sigma for run, _, _, _, _, sigma in self.items}

    def model(self, values, run_dt, h) -> ParallelModel:
        spec = self.spec.with_values({k: v for k, v in values.items() if k != DELAY})
        return ParallelModel(spec.build_elements(run_dt, h), run_dt, spec.name, spec)

    def predict(self, values) -> list:
        """The model force [N] over each item's model input, for parameter ``values`` (name -> SI value).

        The elements act in parallel, so each one's force over an item depends on its own parameters alone: it is
        kept (``ELEMENT_CACHE`` of them) and a Jacobian column that moves one element's parameter runs only that
        element (a load-cell delay, none). The sum is the ParallelModel's to round-off.
        """
        spec = self.spec.with_values({k: v for k, v in values.items() if k != DELAY})
        out = []
        for item, (run, x, h, _, _, _) in enumerate(self.items):
            total = None
            for index, element in enumerate(spec.elements):
                key = (item, index, element.type, repr(sorted(element.values.items())),
                       repr(sorted(element.options.items())))
                force = self._element_forces.get(key)
                if force is None:
                    model = ParallelModel([spec.build_element(index, run.dt, h)], run.dt, spec.name, spec)
                    force = self._element_forces[key] = model.run(x)
                    if len(self._element_forces) > ELEMENT_CACHE * len(self.items) * len(spec.elements):
                        self._element_forces.popitem(last=False)
                else:
                    self._element_forces.move_to_end(key)
                total = force.copy() if total is None else total + force
            out.append(total)
        return out

    def residuals_from(self, predictions, delay=0.0):
        out = []
        for item, pred, base in zip(self.items, predictions, self.base_delay, strict=True):
            run, _, _, force, windows, sigma = item
            shift = (delay + base) / run.dt
            for idx in windows:
                if shift:
                    pos = np.clip(idx - shift, 0, pred.size - 1.000001)
                    i0 = pos.astype(int)
                    frac = pos - i0
                    p = pred[i0] * (1 - frac) + pred[i0 + 1] * frac
                else:
                    p = pred[idx]
                e = p - force[idx]
                out.append((e - e.mean()) / sigma)
        r = np.concatenate(out)
        return np.where(np.isfinite(r), r, 1e6)

    def input_noise(self, values, predictions, seed: int = 0) -> list:
        """Per item: (sigma [N], lag-1 autocorrelation) of the force residual that the displacement transducer's
        own noise causes through the model (errors in variables), at the residual's points.

        The model runs over the measured displacement, so that displacement's noise reaches the model force
        through the model's stiffness at the noise frequencies the input low-pass keeps (0.2 um on a 14 kN/mm
        specimen: ~3 N beside a 10 N load cell). Measured by running the model once more over the displacement
        plus white noise of the same level (noise.band_noise), through the same low-pass: the difference from
        ``predictions`` (TimeProblem.predict at ``values``) is one more realisation of that propagated noise
        (the model is linear in small input changes). The low-pass makes it coloured: its autocorrelation
        between neighbouring analysed points is what a correct model's residual shows too
        (structure.residual_structure).
        """
        rng = np.random.default_rng(seed)
        out = []
        for (run, _x, h, force, windows, _), f_max, pred, est in zip(self.items, self.f_max, predictions,
                                                                     self.noise_estimates, strict=True):
            raw = np.asarray(run.displacement[:force.size], float)
            sx = est['displacement'].sigma
            if sx <= 0:
                out.append((0.0, 0.0))
                continue
            x2, _ = model_input(raw + rng.normal(0.0, sx, raw.size), run.dt, f_max, sx)
            try:
                d = self.model(values, run.dt, h).run(x2) - pred
            except ValueError:
                out.append((0.0, 0.0))
                continue
            parts = [d[idx] - d[idx].mean() for idx in windows]
            power = sum(float(p @ p) for p in parts)
            lag1 = sum(float(p[1:] @ p[:-1]) for p in parts) / power if power > 0 else 0.0
            out.append((float(np.sqrt(np.mean(np.concatenate(parts) ** 2))), lag1))
        return out

    def residuals(self, values):
        values = dict(values)
        delay = float(values.get(DELAY, 0.0))
        try:
            preds = self.predict(values)
        except ValueError:     # parameters the elements refuse (e.g. beyond an asymptote): far from the data
            return np.full(self.m, 1e6)
        return self.residuals_from(preds, delay)


def fit_time_model(problem: TimeProblem, coords: Coordinates, start_z, span=1.0, max_nfev=80):
    """Least squares on the time-domain residuals from ``start_z`` within +-span of it (log coordinates)."""
    lo = np.maximum(coords.lo, start_z - span)
    hi = np.minimum(coords.hi, start_z + span)
    lo = np.where(np.array(coords.kinds) == 'order', np.maximum(coords.lo, start_z - 0.3), lo)
    hi = np.where(np.array(coords.kinds) == 'order', np.minimum(coords.hi, start_z + 0.3), hi)
    delay_kind = np.array(coords.kinds) == 'delay'
    lo, hi = np.where(delay_kind, coords.lo, lo), np.where(delay_kind, coords.hi, hi)
    z0 = np.clip(start_z, lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))

    def fun(z):
        return problem.residuals(coords.values(z))

    ls = least_squares(fun, z0, bounds=(lo, hi), method='trf', diff_step=1e-4, xtol=1e-10, ftol=1e-10,
                       gtol=1e-10, max_nfev=max_nfev, callback=stall_stop())
    return ls, (lo, hi)


# ---- uncertainty -----------------------------------------------------------------------------------

def jacobian(fun, z, eps=1e-3):
    cols = []
    for i in range(z.size):
        up, down = z.copy(), z.copy()
        up[i] += eps
        down[i] -= eps
        cols.append((fun(up) - fun(down)) / (2 * eps))
    return np.column_stack(cols)


def _leave_out_shift(info, bread, jac_b, r_b):
    """How far leaving one block out moves the estimate: one Gauss-Newton step from the full fit,
    (J^T J - J_b^T J_b)^-1 J_b^T r_b (exact for a model linear in its parameters). Where the other blocks
    alone leave a direction undetermined the step falls back to the plain sandwich's (J^T J)^-1 J_b^T r_b.
    """
    g = jac_b.T @ r_b
    rest = info - jac_b.T @ jac_b
    d = np.sqrt(np.clip(np.diag(info), 1e-300, None))    # judged on the correlation scale, not the units
    if np.linalg.cond(rest / np.outer(d, d)) < 1e10:
        return np.linalg.solve(rest, g)
    return bread @ g


def covariance(jac, r, block_rows, n_offsets=0):
    """(noise covariance inflated by the lack of fit, block jackknife covariance, chi2, dof) in coordinates.

    ``block_rows``: the rows of each block (cluster). The block term is the linearised leave-one-block-out
    jackknife (CR3, MacKinnon, Nielsen & Webb 2023 recommend it over CR1 for few or unequal clusters).
    """
    m, n = jac.shape
    dof = max(m - n - n_offsets, 1)
    chi2 = float(r @ r)
    info = jac.T @ jac
    bread = np.linalg.pinv(info)
    cov_noise = bread * max(1.0, chi2 / dof)
    shifts = np.array([_leave_out_shift(info, bread, jac[rows], r[rows]) for rows in block_rows]).reshape(-1, n)
    nb = shifts.shape[0]
    dev = shifts - shifts.mean(axis=0)
    cov_blocks = dev.T @ dev * ((nb - 1) / nb) if nb > 1 else np.zeros((n, n))
    return cov_noise, cov_blocks, chi2, dof


def physical_uncertainty(coords: Coordinates, z, cov_noise, cov_blocks, n_blocks: int = 0):
    """Per parameter: value, sigma (larger of noise and blocks), both sigmas, 95 % interval; correlation.

    The interval is +-t sigma with t the 97.5 % quantile of Student's t with n_blocks - 1 degrees of freedom
    (the block jackknife variance is estimated from that many blocks; 1.96 without blocks).
    """
    def phys(zz):
        v = coords.values(zz)
        return np.array([v[n] for n in coords.names])

    p0 = phys(z)
    tj = np.column_stack([(phys(z + e) - phys(z - e)) / 2e-6 for e in np.eye(z.size) * 1e-6])
    cn = tj @ cov_noise @ tj.T
    cb = tj @ cov_blocks @ tj.T
    sn, sb = np.sqrt(np.clip(np.diag(cn), 0, None)), np.sqrt(np.clip(np.diag(cb), 0, None))
    sigma = np.maximum(sn, sb)
    t95 = float(student_t.ppf(0.975, n_blocks - 1)) if n_blocks > 1 else Z95
    out = {}
    for i, name in enumerate(coords.names):
        rel = sigma[i] / abs(p0[i]) if p0[i] else math.inf
        out[name] = {'value': float(p0[i]), 'sigma': float(sigma[i]), 'relative_sigma': float(rel),
                     'sigma_noise': float(sn[i]), 'sigma_blocks': float(sb[i]),
                     'interval_95': [float(p0[i] - t95 * sigma[i]), float(p0[i] + t95 * sigma[i])]}
    cov = np.where(np.outer(sn, sn) > 0, cn, 0.0)
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = cov / np.outer(sn, sn)
    return out, np.nan_to_num(corr)


def paper_unit(spec: ModelSpec, name: str) -> tuple:
    """(factor from SI, unit) of parameter ``name`` of ``spec`` in the papers' units (kN/mm, mm, kN, ms ...)."""
    if name == DELAY:
        return PAPER_UNITS['delay']
    return PAPER_UNITS.get(spec.param_spec(name).scale, (1.0, 'SI'))


# ---- result ----------------------------------------------------------------------------------------

@dataclass
class ModelFit:
    """One identification (one temperature) of one model."""

    model: ModelSpec               # the fitted model (values replaced)
    temperature: float | None
    runs: list
    blocks: list
    method: str
    parameters: dict               # free parameter name -> value (SI), load_cell_delay included if estimated
    uncertainty: dict              # name -> {sigma, relative_sigma, interval_95, sigma_noise, sigma_blocks}
    correlation: list
    chi2: float
    dof: int
    n_points: int
    noise: dict                    # recording -> load-cell noise sigma [N]
    load_cell: dict                # delay [s], gain [-], delay_estimated
    quality: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    messages: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    truth: dict | None = None
    bounds_hit: list = field(default_factory=list)   # parameters that ended at a search bound
    refinement_limited: list = field(default_factory=list)   # ... at the time-domain fit's range around its start
    notes: list = field(default_factory=list)        # not defects, worth knowing (correlated pairs)
    misfit: dict = field(default_factory=dict)       # the misfit test (misfit.misfit_test)
    noise_estimates: dict = field(default_factory=dict)   # recording -> {force, displacement}: noise.NoiseEstimate
    temperature_records: dict = field(default_factory=dict)   # recording -> temperature.resolve: which was used
    model_temperature: float | None = None           # the temperature the fitted model file states (fixed values)
    fixed: list = field(default_factory=list)        # the model's parameters held at their given values
    diagnoses: dict = field(default_factory=dict)    # non-stationarity, outliers, saturation (fitting.diagnoses)
    band: dict = field(default_factory=dict)         # the measured frequency [Hz] and amplitude [m] ranges

    @property
    def chi2_per_dof(self) -> float:
        """The misfit test's chi^2/dof (misfit.misfit_test: against the whole noise, the load cell's and the
        displacement noise carried through the model), the one figure the CLI, the JSON, the model file and the
        report state; chi2 / dof against the load cell alone where no test was made (``chi2`` keeps that sum
        for AIC and BIC).
        """
        ratio = (self.misfit or {}).get('ratio')
        return float(ratio) if ratio is not None else self.chi2 / max(self.dof, 1)

    @property
    def misfit_summary(self) -> str:
        """The misfit test in one sentence (misfit.misfit_sentence), as everywhere."""
        return misfit_sentence(self.misfit)

    @property
    def n_params(self) -> int:
        return len(self.parameters)

    @property
    def aic(self) -> float:
        return self.chi2 + 2 * self.n_params

    @property
    def bic(self) -> float:
        return self.chi2 + self.n_params * math.log(max(self.n_points, 1))

    def max_errors(self, kind='simulated'):
        ek = [abs(q[kind]['e_k']) for q in self.quality if kind in q]
        ec = [abs(q[kind]['e_c']) for q in self.quality if kind in q]
        return (max(ek) if ek else math.nan), (max(ec) if ec else math.nan)

    def as_dict(self) -> dict:
        out = {'model': self.model.name, 'temperature': self.temperature, 'recordings': self.runs,
               'method': self.method, 'parameters': self.parameters, 'uncertainty': self.uncertainty,
               'warnings': [warning_dict(w) for w in self.warnings], 'misfit': self.misfit, 'notes': self.notes,
               'chi2_per_dof': self.chi2_per_dof, 'misfit_summary': self.misfit_summary, 'chi2': self.chi2,
               'dof': self.dof,
               'n_points': self.n_points, 'n_params': self.n_params, 'aic': self.aic, 'bic': self.bic,
               'noise': {'force_sigma': self.noise, 'estimates': self.noise_estimates}, 'load_cell': self.load_cell,
               'correlation': {'names': list(self.uncertainty), 'matrix': self.correlation},
               'model_file': self.model.to_dict(self.uncertainty), 'blocks': self.quality,
               'timings': self.timings, 'messages': self.messages,
               'temperature_record': self.temperature_records, 'diagnoses': self.diagnoses, 'band': self.band}
        if self.truth:
            out['truth'] = self.truth
            out['errors'] = {k: self.parameters[k] / self.truth[k] - 1.0 for k in self.parameters
                             if self.truth.get(k)}
            out['covered'] = {k: bool(u['interval_95'][0] <= self.truth[k] <= u['interval_95'][1])
                              for k, u in self.uncertainty.items() if k in self.truth}
        return out
