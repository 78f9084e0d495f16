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

"""The displacement the time-domain fit runs its model on (`rubber_rig.fitting.modelfit.TimeProblem`).

The model runs over the whole measured displacement, so its fractional memory and friction reference
state see the same history as the specimen did. That displacement is the measured one after a zero-phase
low-pass (4th-order Butterworth, forward-backward, cut-off 8x the highest block frequency), and the model
runs with Berg's reversal deadband (5x the displacement noise level, at least 2e-4 of the amplitude): raw
transducer noise makes Berg's element see spurious velocity reversals and reset its reference state, which
biases x2 and F_fmax by tens of per cent (0.5 um noise on a 1 mm sine, 1 kHz); low-pass alone still leaves
micro-reversals at the turning points. The x2-F_fmax valley is flat (the initial friction slope
F_fmax/x2 is what the loops pin down), so input errors of 1e-4 of the amplitude would move x2 and F_fmax
together by a few per cent.
"""
from __future__ import annotations

import numpy as np
from scipy.signal import butter, sosfiltfilt

from .blocks import noise_level
from .noise import band_noise, block_windows


def model_input(x, dt, f_max, noise=None):
    """(displacement [m], reversal threshold [m]) to run the model on for a measured displacement ``x``:
    zero-phase low-pass, and Berg's reversal deadband at the noise-sized reversals of x (5x its noise
    level ``noise`` [m], at least 2e-4 of its amplitude). ``noise`` None: the third differences of x
    (`blocks.noise_level`), which the signal inflates at high frequency (0.43 um for 0.2 um at 20-50 Hz).
    """
    x = np.asarray(x, float)
    fs = 1.0 / dt
    fc = min(8.0 * f_max, 0.4 * fs)
    y = x
    if 0 < fc < 0.5 * fs and x.size > 30:
        y = sosfiltfilt(butter(4, fc, fs=fs, output='sos'), x)
    sigma = noise_level(x) if noise is None else float(noise)
    h = max(5.0 * sigma, 2e-4 * float(np.max(np.abs(x - np.median(x))) or 1.0))
    return y, h


def run_input(run, blocks, until: int = 0, noise=None):
    """(end, x, h): the model input (`model_input`, at the blocks' highest frequency) for the measured
    displacement of ``run`` (RunData) up to the closing sample of the last of its ``blocks`` (or to
    sample ``until`` if that is later), i.e. samples [0, end). ``noise``: the displacement's noise [m]; None:
    measured on the blocks with their excitation harmonics removed (`noise.band_noise`).
    """
    end = min(max(max(b.stop for b in blocks) + 1, until), run.displacement.size)
    if noise is None:
        noise = band_noise(run.displacement, run.dt, block_windows(blocks)).sigma
    x, h = model_input(run.displacement[:end], run.dt, max(b.frequency for b in blocks), noise)
    return end, x, h
