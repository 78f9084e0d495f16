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

* ``non_stationary`` (:func:`drift_across_blocks`): the per-block K_dyn (C_eq) errors of the fitted model
  regressed on the blocks' time order *together with* ln f and the amplitude; a time trend beyond
  ``DRIFT_SIGMAS`` of its standard error and above ``PATTERN_K`` / ``PATTERN_C`` over the test is the specimen
  changing (heating, a settling preload, wear), not a frequency or amplitude dependence the model misses: the
  frequency and amplitude terms take those. Time is each block's middle sample (recordings in name order):
  blocks of equal cycles last 1/f each, so time is not a function of ln f and amplitude even for log-spaced
  sweeps; where it is (too few blocks, time collinear), nothing is said.
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

from .noise import OUTLIER_Z

DRIFT_SIGMAS = 4.0     # standard errors of the time trend before it is a drift
PATTERN_K, PATTERN_C = 0.005, 0.025     # the smallest drift worth a warning over the test (as verdict's patterns)
MIN_OUTLIERS = 3
MISFIT_P = 1e-3
FLAT_RUN = 3           # consecutive samples at the extreme
FLAT_RUNS = 2          # separate places (cycles) where it happens
EDGE_QUANTA = 3        # a clip is entered and left by more than this many resolution steps


def drift_across_blocks(rows, blocks) -> dict:
    """The time trend of the per-block errors, frequency and amplitude dependence taken out.

    rows: the fit's per-block quality (group_fit.block_quality), each with 'simulated' or 'analytic' {e_k, e_c}
    and 'measured' {rel_sigma_k, rel_sigma_c}; blocks: the BlockResults in the same order (recording, start).
    Returns {'K_dyn': {change, se, drift}, 'C_eq': {...}, 'blocks': B} where change is the fitted change of the
    relative error from the first to the last block in time; {} when the blocks cannot tell time from frequency
    and amplitude (fewer than 6 blocks, no time stamps, or time collinear with them).
    """
    kind = 'simulated' if any('simulated' in q for q in rows) else 'analytic'
    use = [(q, b) for q, b in zip(rows, blocks, strict=True) if kind in q]
    if len(use) < 6 or all(b.start == 0 for _, b in use):
        return {}
    # time is the blocks' middle sample, recordings one after another in name order: a grid's blocks last
    # 1/f each, so time is not a function of ln f and amplitude even where the block order is (log-spaced sweeps)
    offset, where = 0, {}
    for name in sorted({str(b.recording) for _, b in use}):
        where[name] = offset
        offset += max(b.stop for _, b in use if str(b.recording) == name)
    rank = np.array([where[str(b.recording)] + 0.5 * (b.start + b.stop) for _, b in use], float)
    lf = np.log([q['frequency'] for q, _ in use])
    amp = np.array([q['amplitude'] for q, _ in use])
    cols = [np.ones(len(use))]
    for c in (lf, amp):
        if np.ptp(c) > 0:
            cols.append((c - c.mean()) / np.ptp(c))
    time = (rank - rank.mean()) / max(np.ptp(rank), 1.0)
    design = np.column_stack(cols + [time])
    if np.linalg.matrix_rank(design) < design.shape[1]:
        return {}
    out = {'blocks': len(use)}
    for name, key, limit in (('K_dyn', 'e_k', PATTERN_K), ('C_eq', 'e_c', PATTERN_C)):
        e = np.array([q[kind][key] for q, _ in use])
        coef, *_ = np.linalg.lstsq(design, e, rcond=None)
        dof = e.size - design.shape[1]
        if dof < 2:
            return {}
        s2 = float(np.sum((e - design @ coef) ** 2)) / dof
        cov = s2 * np.linalg.inv(design.T @ design)
        change, se = float(coef[-1]), math.sqrt(max(float(cov[-1, -1]), 0.0))
        out[name] = {'change': change, 'se': se,
                     'drift': abs(change) > limit and abs(change) > DRIFT_SIGMAS * max(se, 1e-300)}
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
    return ('the specimen changed during the test: the model\'s per-block error drifts with the blocks\' time '
            f'order over {drift["blocks"]} blocks, frequency and amplitude taken out: it moved {"; ".join(parts)} '
            f'from the first block to the last{heat} (heating, a settling preload, wear); the parameters are an '
            'average over a moving specimen: condition it longer or fit the blocks in time groups')


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
