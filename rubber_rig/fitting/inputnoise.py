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
* it grows in proportion to the noise: x2 +0.45, +0.9, +1.8 % for 0.1, 0.2, 0.4 um added to a noise-free record
  (two realisations each, +-0.5 % between them); 12 seeds recorded with and without 0.2 um of noise (same force
  noise): x2 +1.0 +- 0.3 %, F_fmax +1.1 +- 0.4 % (paired differences);
* a per-fit estimate by simulation (adding noise once more and refitting linearly, the first step of SIMEX) is
  right in each realisation (one Gauss-Newton step reproduced a refit's +2.50 % against +2.56 %) but the
  realisations scatter by 1.2 % each, so eight of them size a 1 % effect no better than +-0.4 %: not used.

So the budget (fitting.budget, ``displacement_noise``) carries the measured effect as a Type B term, scaled with
the mechanism's two lengths, the displacement noise sigma_x (noise.band_noise of the record) and x2:
u(x2) / x2 = ``X2_PER_NOISE`` sigma_x / x2 and u(F_fmax) / F_fmax = ``FMAX_PER_NOISE`` sigma_x / x2 (70 and 78:
1.0 % and 1.1 % at 0.2 um on x2 = 1.41 mm). A systematic effect estimated and not corrected: its full size is the
standard uncertainty; it widens the interval and leaves the value alone. Its scaling beyond that specimen class
(other x2, amplitudes, sampling rates) is a model, not a measurement.
"""
from __future__ import annotations

X2_PER_NOISE = 70.0       # relative shift of x2 per (sigma_x / x2): 1.0 % at 0.2 um on x2 = 1.41 mm
FMAX_PER_NOISE = 78.0     # relative shift of F_fmax per (sigma_x / x2): 1.1 % at 0.2 um on x2 = 1.41 mm


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
        names = {p: n for n, i, p in spec.parameters() if i == index}
        x2 = values.get(names.get('x2'), element.values.get('x2'))
        if not x2 or x2 <= 0:
            continue
        ratio = sigma_x / x2
        if names.get('x2') in values:
            out[names['x2']] = X2_PER_NOISE * ratio * abs(values[names['x2']])
        if names.get('f_fmax') in values:
            out[names['f_fmax']] = FMAX_PER_NOISE * ratio * abs(values[names['f_fmax']])
    return out
