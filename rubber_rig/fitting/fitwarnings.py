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

"""Structured warnings of an identification: a sentence for people, a code and parameters for programs.

A FitWarning is the sentence itself (a ``str``: the table, the report and every caller that prints or
searches warnings keep working) carrying ``code`` and ``parameters``; ``fit --json`` and the model file write
``{code, message, parameters}`` objects (:func:`warning_dict`). Codes:

=====================  ==============================================================================
misfit                 the model does not describe the data to their noise (the statistical test, a
                       per-block error beyond target and noise, a systematic residual pattern)
identifiability        the data do not determine a parameter, or only a combination of two
bounds                 a parameter ended at the edge of its search range
delay                  a load-cell delay estimated from the data, beyond the declared one
calibration_undeclared a transducer calibration the fit needs was not declared
calibration_disagrees  a calibration estimated from the data disagrees with the declared one
short_blocks           too few settled cycles per block for unbiased parameters
noise_overstated       chi^2 below what the noise allows (two-sided misfit test): the noise judged against
                       was overstated, so the misfit test is blind by that much
temperature_disagrees  the metadata, the temperature channel or the model's fixed values state different
                       temperatures beyond their uncertainties; the fit names both and which it used
non_stationary         the specimen changed during the test: the per-block errors drift in time order with
                       frequency and amplitude taken out (heating, settling, wear)
outliers               spikes: residual samples beyond 6 noise sigmas, more than white noise gives
saturation             a clipped channel: it holds its extreme value exactly in flat tops
extrapolation          a limit parameter (K0 at 0 Hz, K_inf) set by the model's shape outside the measured
                       band by more than its stated uncertainty
=====================  ==============================================================================
"""
from __future__ import annotations

CODES = ('misfit', 'identifiability', 'bounds', 'delay', 'calibration_undeclared', 'calibration_disagrees',
         'short_blocks', 'noise_overstated', 'temperature_disagrees', 'non_stationary', 'outliers', 'saturation',
         'extrapolation')


class FitWarning(str):
    """A warning sentence with its ``code`` (one of CODES) and the ``parameters`` it concerns."""

    def __new__(cls, code: str, message: str, parameters=()):
        if code not in CODES:
            raise ValueError(f'unknown warning code {code!r} (one of {", ".join(CODES)})')
        obj = super().__new__(cls, message)
        obj.code = code
        obj.parameters = [str(p) for p in parameters]
        return obj

    def __getnewargs__(self):       # copy and pickle (parallel fits) rebuild it with its code
        return self.code, str(self), self.parameters


def warning_text(w) -> str:
    """The sentence of a warning: a FitWarning, a plain string or a ``{code, message, ...}`` mapping (as a model
    file stores it).
    """
    return str(w.get('message', '')) if isinstance(w, dict) else str(w)


def warning_dict(w) -> dict:
    """``{code, message, parameters}`` of a FitWarning; a plain string (a model file written before codes
    existed) gets code ``None``.
    """
    return {'code': getattr(w, 'code', None), 'message': str(w), 'parameters': list(getattr(w, 'parameters', []))}
