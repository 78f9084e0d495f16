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

"""When the time-domain refinement has converged: a statistical stop for `fitting.modelfit.fit_time_model`."""
from __future__ import annotations

STALL_CHI2 = 0.01        # chi^2 gained over STALL_ITERATIONS iterations below which the refinement has converged
STALL_ITERATIONS = 5


def stall_stop():
    """A least_squares callback that ends the refinement once chi^2 (residuals in noise units: 2 x cost) has
    fallen by less than ``STALL_CHI2`` over the last ``STALL_ITERATIONS`` iterations.

    Why a statistical stop: where the likelihood is locally quadratic, a Gauss-Newton step that lowers chi^2 by
    Delta moves the parameters by about sqrt(Delta) standard deviations (chi^2 rises by 1 at one sigma), so five
    steps that together gain less than 0.01 move them by about a tenth of a sigma or less; the relative
    tolerances alone let a fit along a flat valley
    (a misfit model, parameters the data hardly constrain) crawl on in steps of 1e-3..1e-6 of chi^2 until the
    evaluation limit: the Maxwell specimen fitted with zener_berg and a free delay spent 50 of its 80
    iterations there (4 s of CPU).
    """
    chi2 = []

    def callback(intermediate_result):
        chi2.append(2.0 * float(intermediate_result.cost))
        if len(chi2) > STALL_ITERATIONS and chi2[-STALL_ITERATIONS - 1] - chi2[-1] < STALL_CHI2:
            raise StopIteration
    return callback
