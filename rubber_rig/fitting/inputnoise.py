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

"""The bias the displacement noise leaves in the parameters (errors in variables), sized per fit: a Type B term.

The time-domain fit runs its model over the *measured* displacement (fitting.timefit: low-passed, with Berg's
reversal deadband at the measured noise). That noise reaches the model force through the model itself, and not
only as scatter (``TimeProblem.input_noise``, the misfit test's share): Berg's element turns at the extremes of
the noisy samples and its branches start from them, so the friction parameters come out shifted on average.
Measured on a stiff, low-alpha specimen (seed 000 at 20 degC, K x 3, alpha 0.35, F_fmax x 0.3; 1 kHz, 0.2 um,
20 N, dynamic_stiffness_grid; 12 seeds, each recorded with and without displacement noise, the same force noise):
x2 +1.0 +- 0.3 % and F_fmax +1.1 +- 0.4 % from the displacement noise (paired differences; a quarter of their
stated sigma), which the intervals did not carry. The rest of the friction error (+0.8 +- 1.6 % without
displacement noise) is consistent with zero (docs/benchmarks/identification_notes.md).

:func:`input_noise_bias` sizes the effect on each fit by the first step of SIMEX (simulation-extrapolation, Cook &
Stefanski 1994): the whole input path is run again with the displacement noise variance doubled (the measured
displacement plus white noise of its own measured level, the deadband at the doubled level), and the fit's
response to that, one Gauss-Newton step at the optimum (budget.linearised_shift), is the bias the noise already in
the record caused (a bias that grows with the noise variance: b(2 s^2) - b(s^2) = b(s^2)). Averaged over
``REPEATS`` realisations. The budget (fitting.budget) carries its size as the Type B term ``displacement_noise``:
a systematic effect estimated and not corrected, so it widens the interval instead of moving the value.
"""
from __future__ import annotations

import math

import numpy as np

from .budget import linearised_shift
from .search import DELAY
from .timefit import model_input

REPEATS = 6      # realisations of the doubled noise (each one model run per recording)


def input_noise_bias(problem, coords, z, jac, values: dict, predictions: list, repeats: int = REPEATS,
                     seed: int = 1) -> dict:
    """Per free parameter (search-coordinate names): {'shift': the bias the displacement noise causes [unit],
    'se': its standard error over the realisations}; {} when no recording has a displacement noise.

    ``problem``: the fit's TimeProblem; ``coords``, ``z``, ``jac``: its coordinates, optimum and the Jacobian of
    the residuals there; ``values``: the fitted values; ``predictions``: TimeProblem.predict(values).
    """
    rng = np.random.default_rng(seed)
    delay = float(values.get(DELAY, 0.0))
    base = problem.residuals_from(predictions, delay)
    noisy = [est['displacement'].sigma > 0 for est in problem.noise_estimates]
    if not any(noisy):
        return {}
    shifts = []
    for _ in range(repeats):
        preds = []
        items = zip(problem.items, problem.f_max, predictions, problem.noise_estimates, noisy, strict=True)
        for (run, _x, _h, force, _w, _s), f_max, pred, est, has in items:
            if not has:
                preds.append(pred)
                continue
            sx = est['displacement'].sigma
            raw = np.asarray(run.displacement[:force.size], float)
            # the record's noise variance doubled: the input path (low-pass, deadband at the noise level) as a
            # record with sqrt(2) x the noise would have had it
            x2, h2 = model_input(raw + rng.normal(0.0, sx, raw.size), run.dt, f_max, math.sqrt(2.0) * sx)
            try:
                preds.append(problem.model(values, run.dt, h2).run(x2))
            except ValueError:
                return {}
        shift, _ = linearised_shift(coords, z, jac, problem.residuals_from(preds, delay) - base)
        shifts.append(shift)
    out = {}
    for name in coords.names:
        s = np.array([sh[name] for sh in shifts])
        out[name] = {'shift': float(s.mean()), 'se': float(s.std(ddof=1) / math.sqrt(s.size)) if s.size > 1 else 0.0}
    return out
