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

"""Block-aware cycle pairing of the element_model node (ROS-free glue): BlockIndex.segments, CyclePairer."""
import numpy as np
import pytest

from rubber_rig.models import build_model
from rubber_rig.online.cycles import CyclePairer
from rubber_rig.online.predictor import BlockIndex


def test_block_index_splits_a_batch_by_block():
    idx = BlockIndex()
    for first, block in ((0, 0), (50, 0), (100, 1), (150, 2)):
        idx.add(first, 50, block)
    assert idx.segments(0, 50) == [(0, 50, 0)]
    assert idx.segments(30, 50) == [(0, 50, 0)]                  # two setpoint batches of one block: one segment
    assert idx.segments(90, 50) == [(0, 10, 0), (10, 50, 1)]
    assert idx.segments(140, 80) == [(0, 10, 1), (10, 60, 2), (60, 80, -1)]   # beyond the setpoints: unknown
    assert idx.segments(500, 10) == [(0, 10, -1)]
    assert sum(hi - lo for lo, hi, _ in idx.segments(20, 170)) == 170


def test_pairer_cuts_cycles_of_each_block_after_a_ramp_to_a_new_preload():
    # seed 004: ramp to -0.9 mm, then a 0.3 mm sine around it. Without the block restart the trigger levels
    # of the ramp (mean -0.45 mm) lie outside the sine and not one cycle would be cut
    dt, f, a, x0 = 1e-3, 4.0, 0.3e-3, -0.9e-3
    ramp = np.linspace(0.0, x0, 1800)
    t = np.arange(2500) * dt
    sine = x0 + a * np.sin(2 * np.pi * f * t)
    x = np.concatenate([ramp, sine])
    blocks = np.concatenate([np.zeros(ramp.size, int), np.ones(sine.size, int)])
    force = build_model('seed000_20C', dt).run(x)
    idx = BlockIndex()
    pairer = CyclePairer(min_amplitude=5e-6)
    cycles = []
    for first in range(0, x.size, 50):                           # 50-sample batches, as the driver sends them
        idx.add(first, 50, int(blocks[first]))
        for lo, hi, block in idx.segments(first, 50):
            s = slice(first + lo, first + hi)
            # the model channel reads 2 % stiffer: the pairer must keep the channels apart on the same cycles
            cycles += [(block, c) for c in pairer.feed(first + lo, dt, x[s], force[s], 1.02 * force[s], block)]
    assert len(cycles) >= 8 and {b for b, _ in cycles} == {1}
    for _, c in cycles:
        assert c.start_sequence >= ramp.size                     # no cycle reaches back into the ramp
        assert c.measured['amplitude'] == pytest.approx(a, rel=2e-3)
        assert c.measured['mean'] == pytest.approx(x0, abs=0.02 * a)
        assert c.model['k_dyn'] == pytest.approx(1.02 * c.measured['k_dyn'], rel=1e-9)
        assert c.model['amplitude'] == c.measured['amplitude']          # one cut, one displacement
    # the same data without block information: the stale levels never trigger
    pairer = CyclePairer(min_amplitude=5e-6)
    assert pairer.feed(0, dt, x, force, 1.02 * force) == []
