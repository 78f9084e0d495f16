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

"""The bias the displacement noise leaves in Berg's friction parameters (errors in variables): a Type B term.

The time-domain fit runs its model over the *measured* displacement (fitting.timefit: low-passed, with Berg's
reversal deadband at the measured noise). Berg's element turns at the extremes of those noisy samples, and its
branches start there, a little beyond where the specimen turned; to match the loops the fit makes x2 and F_fmax
larger. Measured on a stiff, low-alpha specimen (seed 000 at 20 degC, K x 3, alpha 0.35, F_fmax x 0.3;
dynamic_stiffness_grid, 1 kHz, 20 N load-cell noise; docs/benchmarks/identification_notes.md):

* the cause is the displacement record alone: the same force record fitted with the noisy and with the noise-free
  displacement differs by the full shift, and fitting the noisy record's blocks with the noise-free displacement as
  the model's input gives the noise-free result exactly (not the deadband: 0.2 or 1 um on a clean input give the
  same fit; not the low-pass or the start of the search);
* it grows in proportion to the noise: x2 +0.45, +0.9, +1.8, +3.9 % for 0.1, 0.2, 0.4, 0.8 um added to a
  noise-free record (means of two realisations, 0.4-3.3 % apart); 12 seeds recorded with and without 0.2 um of
  noise (same force noise): x2 +0.98 +- 0.25 %, F_fmax +1.14 +- 0.30 % (paired differences);
* a per-fit estimate by simulation (adding noise once more and refitting linearly, the first step of SIMEX) is
  right in each realisation (one Gauss-Newton step reproduced a refit's +2.50 % against +2.56 %) but the
  realisations scatter by 1.2 % each, so eight of them size a 1 % effect no better than +-0.4 %: not used.

The same paired experiment on seed 003's specimen (x2 0.30 mm, 1-50 Hz x 0.2-0.5 mm, orders fixed, 6 seeds):
x2 and F_fmax +0.17 +- 0.09 %. The size depends on the specimen and the program (not simply on sigma_x / x2, which
would predict 4.7 % there), so the budget (fitting.budget, ``displacement_noise``) carries the larger of the two
measured effects in proportion to the record's displacement noise sigma_x (noise.band_noise): u(x2) / x2 =
``X2_PER_NOISE`` sigma_x and u(F_fmax) / F_fmax = ``FMAX_PER_NOISE`` sigma_x (1.0 % and 1.14 % at 0.2 um). A
systematic effect estimated and not corrected: its full size is the standard uncertainty; it widens the interval
and leaves the value alone; for specimens like seed 003's it is an upper bound (6 x what was measured there).
"""
from __future__ import annotations

X2_PER_NOISE = 5.0e4     # relative shift of x2 per metre of displacement noise: 1.0 % at 0.2 um
FMAX_PER_NOISE = 5.7e4    # relative shift of F_fmax per metre of displacement noise: 1.14 % at 0.2 um


def berg_input_noise(spec, values: dict, sigma_x: float) -> dict:
    """Type B standard uncertainties [SI] of the Berg elements' free x2 and F_fmax in ``values`` (name -> value)
    for the displacement noise ``sigma_x`` [m] of the record(s) the model ran over: {name: u}; {} without noise.
    """
    if not sigma_x or sigma_x <= 0:
        return {}
    out = {}
    for index, element in enumerate(spec.elements):
        if element.type != 'berg':
            continue
        for name, i, p in spec.parameters():
            if i != index or name not in values:
                continue
            if p == 'x2':
                out[name] = X2_PER_NOISE * sigma_x * abs(values[name])
            elif p == 'f_fmax':
                out[name] = FMAX_PER_NOISE * sigma_x * abs(values[name])
    return out
