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

"""Diagnoses named for what they are: a specimen that changes during the test, spikes, a clipped sensor.

Each also makes the model misfit (and the misfit warning stays); these name the cause, each with its own
warning code (fitwarnings):

* ``non_stationary`` (:func:`drift_within_blocks`): the fitted model's error of K_dyn (C_eq) cycle by cycle inside
  each block, where frequency and amplitude do not change, regressed on time with each block's own mean removed; a
  common slope beyond ``DRIFT_SIGMAS`` of its standard error and above ``PATTERN_K`` / ``PATTERN_C`` over the
  blocks' time span is the specimen changing (heating, a settling preload, wear). A model that misses something
  (a branch, a nonlinearity) errs by the same amount in every cycle of a block: that is the misfit warning's, not a
  drift (it was, regressed across blocks: the missing branch's curvature in ln f aliased onto block time).
* ``outliers`` (:func:`outlier_test`): samples of the excitation-harmonic-free residual (noise.band_noise)
  beyond ``noise.OUTLIER_Z`` robust sigmas; white noise puts 2e-9 of its samples there, so a count whose
  Poisson p-value is below ``MISFIT_P`` (and at least ``MIN_OUTLIERS``) is spikes (EMI, a loose connector, a
  dropped bit), which a least-squares fit spreads over every parameter.
* ``saturation`` (:func:`flat_tops`): a channel that sits at exactly its extreme value for at least
  ``FLAT_RUN`` consecutive samples, in at least ``FLAT_RUNS`` places, reached by a step of more than
  ``EDGE_QUANTA`` of its resolution: a transducer or amplifier clipped (a noisy measurement never repeats its
  maximum; a clipped one holds it, arriving with its full slope; a quiet quantised one holds a smooth peak too,
  but steps onto it by one quantum). The force there is not the specimen's.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.stats import norm, poisson

from .metrics import window_properties
from .noise import OUTLIER_Z

DRIFT_SIGMAS = 4.0     # standard errors of the time trend before it is a drift
MIN_DRIFT_CYCLES = 4   # cycles a block needs to show a trend inside it (2 for the block mean and the slope, 2 more)
MIN_DRIFT_BLOCKS = 2
PATTERN_K, PATTERN_C = 0.005, 0.025     # the smallest drift worth a warning over the test (as verdict's patterns)
MIN_OUTLIERS = 3
MISFIT_P = 1e-3
FLAT_RUN = 3           # consecutive samples at the extreme
FLAT_RUNS = 2          # separate places (cycles) where it happens
EDGE_QUANTA = 3        # a clip is entered and left by more than this many resolution steps


def _cycle_errors(blocks, runs: dict, forces: dict, noise: dict) -> tuple:
    """(columns, blocks used, first and last cycle time [s]) for :func:`drift_within_blocks`: per analysed cycle
    of each block with at least ``MIN_DRIFT_CYCLES`` cycles, e_k and e_c (model / measured - 1), its time, its
    weights (inverse first-harmonic noise variance of e_k, e_c) and its block's number.
    """
    cols = {'e_k': [], 'e_c': [], 't': [], 'w_k': [], 'w_c': [], 'block': []}
    used, t_first, t_last, offset = 0, None, None, 0.0
    starts = {}
    for name in sorted({str(b.recording) for b in blocks}):       # recordings one after another, in name order
        starts[name] = offset
        offset += runs[name].force.size * runs[name].dt if name in runs else 0.0
    for b in blocks:
        run, model = runs.get(b.recording), forces.get(b.recording)
        if run is None or model is None or b.cycles < MIN_DRIFT_CYCLES:
            continue
        length = (b.stop - b.start) / b.cycles
        sigma = max(float(noise.get(b.recording, 0.0)), 1e-12)
        rows = 0
        for c in range(b.cycles):
            s = b.start + int(round(c * length))
            e = min(b.start + int(math.ceil((c + 1) * length)), run.force.size - 1)
            try:
                meas = window_properties(run.displacement, run.force, run.dt, s, e, b.frequency)
                mod = window_properties(run.displacement, model, run.dt, s, e, b.frequency)
            except ValueError:        # a cycle cut short (the record's end)
                continue
            if not (meas['k_dyn'] and meas['c_eq']):
                continue
            t = starts[str(b.recording)] + 0.5 * (s + e) * run.dt
            cols['e_k'].append(mod['k_dyn'] / meas['k_dyn'] - 1)
            cols['e_c'].append(mod['c_eq'] / meas['c_eq'] - 1)
            cols['t'].append(t)
            # one cycle's first-harmonic noise, relative: sigma sqrt(2 / N) / (K_dyn A), and / (w C_eq A) for C_eq
            cols['w_k'].append((e - s) * (meas['k_dyn'] * b.amplitude / sigma) ** 2 / 2.0)
            cols['w_c'].append((e - s) * (2 * math.pi * b.frequency * meas['c_eq'] * b.amplitude / sigma) ** 2 / 2.0)
            cols['block'].append(used)
            rows += 1
        if rows >= MIN_DRIFT_CYCLES:
            used += 1
            t_first = min(t_first if t_first is not None else math.inf, cols['t'][-rows])
            t_last = max(t_last if t_last is not None else -math.inf, cols['t'][-1])
        else:
            for key in cols:
                del cols[key][len(cols[key]) - rows:]
    return cols, used, t_first, t_last


def drift_within_blocks(blocks, runs: dict, forces: dict, noise: dict) -> dict:
    """The specimen's change in time, measured inside the blocks, where frequency and amplitude are constant.

    blocks: the fit's BlockResults; runs: recording name -> RunData; forces: recording name -> the fitted model's
    force over that recording's measured displacement (what the fit compared with); noise: recording name ->
    load-cell noise sigma [N]. Each analysed cycle of a block gets its relative errors e = model / measured - 1 of
    K_dyn and C_eq (seed 000 Eq. 28, one cycle at a time); a block's own mean is removed (whatever the model gets
    wrong at that frequency and amplitude: a missing branch, a missing nonlinearity, is the same in every cycle of
    the block), and the slope of e against time is fitted over all blocks together, each cycle weighted by its
    first-harmonic noise (``blocks.harmonic_sigma``: samples per cycle, force amplitude), the residual scatter
    scaling its standard error. Returns {'K_dyn': {'change', 'se', 'drift'}, 'C_eq': {...}, 'blocks': B,
    'duration': T [s]} with change = slope x T, the change over the blocks' span T; {} with fewer than
    ``MIN_DRIFT_BLOCKS`` blocks of at least ``MIN_DRIFT_CYCLES`` cycles.

    Why inside the blocks: regressed across blocks on time with ln f and the amplitude, the per-block error of a
    model that misses a branch (the Maxwell specimen fitted with zener_berg) or a cubic term is curved in ln f, and
    on a grid whose amplitudes are swept one after the other the block time is a smooth function of frequency and
    amplitude: the curvature passed for a drift of 44 % in C_eq. Inside a block the model's error is constant for a
    stationary specimen and grows for a heating one.
    """
    cols, used, t_first, t_last = _cycle_errors(blocks, runs, forces, noise)
    if used < MIN_DRIFT_BLOCKS:
        return {}
    block = np.asarray(cols['block'])
    t = np.asarray(cols['t'])
    duration = float(t_last - t_first)
    out = {'blocks': used, 'duration': duration}
    for label, key, limit in (('K_dyn', 'e_k', PATTERN_K), ('C_eq', 'e_c', PATTERN_C)):
        e, w = np.asarray(cols[key]), np.asarray(cols['w' + key[1:]])
        # each block's own (weighted) mean removed from e and t: only the change inside the blocks is left
        sw = np.bincount(block, w)
        ec = e - (np.bincount(block, w * e) / sw)[block]
        tc = t - (np.bincount(block, w * t) / sw)[block]
        stt = float(np.sum(w * tc * tc))
        dof = e.size - used - 1
        if stt <= 0 or dof < 2:
            return {}
        slope = float(np.sum(w * tc * ec)) / stt
        s2 = float(np.sum(w * (ec - slope * tc) ** 2)) / dof        # scatter beyond noise widens the error
        se = math.sqrt(max(s2, 1.0) / stt)
        change = slope * duration
        out[label] = {'change': change, 'se': se * duration,
                      'drift': abs(change) > limit and abs(slope) > DRIFT_SIGMAS * max(se, 1e-300)}
    return out


def drift_sentence(drift: dict, temperature_std=None) -> str | None:
    """The non_stationary warning's sentence, or None."""
    moved = [(n, d) for n, d in drift.items() if isinstance(d, dict) and d.get('drift')]
    if not moved:
        return None
    # e = model / measured - 1: a specimen that softens leaves an error that grows; its own change is -e's
    parts = [f'its {n} by {-100 * d["change"]:+.2f} % relative to the model '
             f'({abs(d["change"]) / max(d["se"], 1e-300):.0f} standard errors)' for n, d in moved]
    heat = (f'; the temperature channel varied by {temperature_std:.2g} K (1 sigma) over the record'
            if temperature_std else '')
    return ('the specimen changed during the test: inside each of its blocks, where frequency and amplitude stay '
            f'the same, the model\'s error drifts with time cycle by cycle ({drift["blocks"]} blocks); at that rate it '
            f'moved {"; ".join(parts)} over the {drift["duration"]:.0f} s from the first block to the last{heat} '
            '(heating, a settling preload, wear); the parameters are an average over a moving specimen: condition '
            'it longer or fit the blocks in time groups')


def outlier_test(estimate: dict) -> dict | None:
    """{count, examined, expected, p_value, largest, largest_at} of a noise estimate (NoiseEstimate.as_dict())
    when its outliers are beyond what white noise gives, else None.
    """
    count, examined = int(estimate.get('outliers', 0)), int(estimate.get('examined', 0))
    if examined <= 0 or count < MIN_OUTLIERS:
        return None
    expected = examined * 2 * float(norm.sf(OUTLIER_Z))
    p = float(poisson.sf(count - 1, expected))
    if p >= MISFIT_P:
        return None
    return {'count': count, 'examined': examined, 'expected': expected, 'p_value': p,
            'largest': estimate.get('largest', 0.0), 'largest_at': estimate.get('largest_at', -1)}


def outlier_sentence(channel: str, recording: str, test: dict, sigma: float, unit: str, dt: float) -> str:
    return (f'{recording}: {test["count"]} {channel} samples of {test["examined"]} examined lie beyond '
            f'{OUTLIER_Z:g} sigma of the noise ({sigma:.3g} {unit}), where white noise puts '
            f'{test["expected"]:.2g} (p = {test["p_value"]:.1g}); the largest is {test["largest"]:.0f} sigma at '
            f't = {test["largest_at"] * dt:.4g} s: spikes (EMI, a loose connector, a dropped bit) that a least-'
            'squares fit spreads over every parameter; find their cause or cut them out of the record')


def flat_tops(x) -> dict | None:
    """{'side': 'max'/'min', 'level', 'runs', 'samples'} when ``x`` (shape (n,)) holds exactly its extreme for
    at least FLAT_RUN consecutive samples in at least FLAT_RUNS places, each entered and left by a step larger
    than ``EDGE_QUANTA`` of the channel's resolution (a clipped channel), else None.

    The step condition separates a clip from a smooth peak read by a quantised channel with little noise: a slow
    sine holds its top value for many samples too (1 mm at 0.5 Hz read to 0.1 um: about 9 samples at 1 kHz),
    but it reaches it by one quantum, where a clipped signal arrives at the limit with its full slope. The
    resolution is the smallest non-zero step between consecutive samples.
    """
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size < 10 or np.ptp(x) <= 0:
        return None
    tol = 1e-9 * float(np.ptp(x))
    steps = np.abs(np.diff(x))
    quantum = float(steps[steps > tol].min()) if np.any(steps > tol) else 0.0
    found = None
    for side, level in (('max', float(x.max())), ('min', float(x.min()))):
        at = np.abs(x - level) <= tol
        edges = np.diff(np.concatenate([[0], at.astype(np.int8), [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        runs = 0
        for a, b in zip(starts, stops, strict=True):
            if b - a < FLAT_RUN:
                continue
            into = [abs(x[i] - level) for i in (a - 1, b) if 0 <= i < x.size]
            if into and min(into) > EDGE_QUANTA * quantum:
                runs += 1
        if runs >= FLAT_RUNS and (found is None or runs > found['runs']):
            found = {'side': side, 'level': level, 'runs': runs, 'samples': int(np.count_nonzero(at))}
    return found


def saturation_sentence(channel: str, recording: str, flat: dict, unit_scale: float, unit: str) -> str:
    which = 'maximum' if flat['side'] == 'max' else 'minimum'
    return (f'{recording}: the {channel} is clipped: it holds its {which}, {flat["level"] * unit_scale:.5g} {unit}, '
            f'exactly for {flat["samples"]} samples in {flat["runs"]} flat tops (a noisy measurement never repeats '
            'its extreme): the transducer or its amplifier saturated, and the force there is not the specimen\'s; '
            'the loops are cut off, so stiffness and loss come out low; reduce the amplitude or re-range the sensor')
