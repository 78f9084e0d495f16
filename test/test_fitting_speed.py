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

"""What makes every fit < 10 s of CPU changes no result: the statistical stop of the refinement, and the element
forces kept between the model runs of a fit (CPU per fit: benchmarks/bench_identification.py)."""
from types import SimpleNamespace

import numpy as np
import pytest

from rubber_rig.fitting.data import _program_blocks, from_arrays
from rubber_rig.fitting.identification import split_runs
from rubber_rig.fitting.modelfit import TimeProblem
from rubber_rig.fitting.simulate import EXACT_SENSORS, run_simulated
from rubber_rig.fitting.stopping import STALL_CHI2, STALL_ITERATIONS, stall_stop
from rubber_rig.models.composite import ParallelModel
from rubber_rig.models.modelfile import named_model


def test_the_refinement_stops_only_once_chi2_has_stalled():
    stop = stall_stop()
    chi2 = [5000.0, 4900.0, 4890.0, 4889.0, 4888.9, 4888.89]
    for c in chi2:
        stop(SimpleNamespace(cost=c / 2))            # still gaining more than 0.01 over 5 iterations
    for k in range(STALL_ITERATIONS - 1):
        stop(SimpleNamespace(cost=(4888.89 - 0.001 * (k + 1)) / 2))
    with pytest.raises(StopIteration):               # 5 iterations gained 0.005 < STALL_CHI2 in total
        stop(SimpleNamespace(cost=(4888.89 - 0.001 * STALL_ITERATIONS) / 2))
    assert 0.001 * STALL_ITERATIONS < STALL_CHI2


@pytest.fixture(scope='module')
def problem():
    spec = named_model('swing_arm_joint_20C').to_dict()
    program = {'name': 'grid', 'defaults': {'taper_cycles': 1, 'cycles': 5, 'mean': 0.0},
               'blocks': [{'name': 'sine', 'waveform': 'sine', 'amplitude': ['0.5 mm', '1 mm'],
                           'frequency': ['1 Hz', '4 Hz', '10 Hz']}]}
    res, text, cfg = run_simulated(program, spec, 20.0, force_noise=20.0, seed=1, config_options=EXACT_SENSORS)
    run = from_arrays('rec', 1 / res.sample_rate, res.displacement, res.force, block_index=res.block_index,
                      program_blocks=_program_blocks(text), temperature=20.0)
    groups, _ = split_runs([run])
    return TimeProblem(named_model('swing_arm_joint_20C'), [(r, b) for r, b, _ in groups[20.0]])


def test_kept_element_forces_equal_the_whole_model_run(problem):
    spec = problem.spec
    values = spec.values()
    run, x, h = problem.items[0][:3]
    whole = ParallelModel(spec.build_elements(run.dt, h), run.dt).run(x)
    first = problem.predict(values)[0]
    np.testing.assert_allclose(first, whole, rtol=1e-13, atol=1e-9)
    kept = len(problem._element_forces)
    assert kept == len(spec.elements)
    # a Berg parameter moved: only the Berg element runs again (one more entry), the answer is still the whole
    # model's
    moved = {**values, 'x2': 1.01 * values['x2']}
    second = problem.predict(moved)[0]
    assert len(problem._element_forces) == kept + 1
    whole2 = ParallelModel(spec.with_values(moved).build_elements(run.dt, h), run.dt).run(x)
    np.testing.assert_allclose(second, whole2, rtol=1e-13, atol=1e-9)
    assert np.max(np.abs(second - first)) > 1.0               # and it did change the force
    np.testing.assert_array_equal(problem.predict(values)[0], first)    # back: the kept forces, bit for bit
