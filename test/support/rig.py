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

"""Shared helpers of the rig tests (not a test module)."""
import numpy as np

from rubber_rig.rig.config import SimOptions
from rubber_rig.rig.sim.plant import Actuator
from rubber_rig.rig.sim.specimen import build_specimen

FAST = {'paced': False}


def expected_plant(result, options: SimOptions = None):
    """Noise-free actuator position [m] and specimen force [N] for the applied commands of a RunResult
    (the run must have no lost samples)."""
    opt = options or SimOptions()
    act = Actuator(opt.actuator_frequency, opt.actuator_damping, opt.actuator_velocity_max, result.sample_rate)
    x = np.array([act.step(u) for u in result.setpoint])
    model = build_specimen(opt.specimen, 1.0 / result.sample_rate)
    f = np.array([model.step(float(v)) for v in x])
    return x, f


def poll_samples(drv, got, n, tries):
    """Poll the driver (at most `tries` times), appending its SampleBlocks to `got`, until `got` holds at least n
    samples and a poll finds nothing more; return the number of samples in `got`."""
    for _ in range(tries):
        b = drv.poll()
        if b is not None:
            got.append(b)
        elif sum(len(g) for g in got) >= n:
            break
    return sum(len(g) for g in got)


def contiguous_diffs(seq, values):
    """np.diff of values only between consecutive sequence numbers (gaps from lost frames skipped)."""
    ok = np.diff(seq) == 1
    return np.diff(values)[ok]


def contiguous_second_diffs(seq, values):
    """Second differences of values only over three consecutive sequence numbers."""
    seq = np.asarray(seq)
    ok = (seq[2:] - seq[:-2]) == 2
    return (values[2:] - 2 * values[1:-1] + values[:-2])[ok]
