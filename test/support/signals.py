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

"""Test signals and loop measures shared by the model and node tests."""
import numpy as np

from rubber_rig.models import sine_displacement

NOISE = 0.2e-6      # [m] displacement noise of the simulated rig (SimOptions.displacement_noise)


def noisy_sine(seed=3, cycles=12, dt=1e-3, frequency=0.5, amplitude=0.5e-3, noise=NOISE):
    x = sine_displacement(frequency, amplitude, dt, cycles)
    return x, x + np.random.default_rng(seed).normal(size=x.size) * noise


def cycle_energy(x, f, per_cycle, cycles=5):
    """Mean loop area (Eq. 18's E_f) [J] of the last ``cycles`` cycles, trapezoid over the input x."""
    xs, fs = x[-(cycles * per_cycle + 1):], f[-(cycles * per_cycle + 1):]
    return np.sum(0.5 * (fs[1:] + fs[:-1]) * np.diff(xs)) / cycles
