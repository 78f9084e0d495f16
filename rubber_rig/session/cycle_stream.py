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

"""The cycles a program's detectors judge, from a ROS-free run: the nodes' pipeline with no ROS in between.

The element model's OnlinePredictor predicts every sample in batches (rig_driver: 10 ms at 1 kHz), the
CyclePairer cuts and pairs the cycles per block, and ``cycle_of`` places each in the program as the excitation
node does. Feed the result to a :class:`~rubber_rig.excitation.detectors.Monitor` (tests, benchmarks).
"""
from __future__ import annotations

import numpy as np

from ..excitation.judged_cycles import Cycle, cycle_of
from ..excitation.runner import ProgramRunner
from ..online import CyclePairer, ModelChoice, OnlinePredictor, cycle_properties
from .run import run_program

BATCH = 10                  # samples per prediction batch (rig_driver: 10 ms at 1 kHz)
MIN_AMPLITUDE = 5e-6        # [m] smallest cycle the pairer keeps (element_model's default)


def cycle_stream(r, program, choice: ModelChoice, force=None) -> list[Cycle]:
    """The Cycles of run `r` (a RunResult of `program`) as the model of `choice` sees them.

    force: the force record to use instead of ``r.force`` [N] (a load-cell fault applied to it,
    rubber_rig.rig.sim.load_cell), one value per sample.
    """
    fs = r.sample_rate
    force = r.force if force is None else np.asarray(force, dtype=float)
    runner = ProgramRunner(program, fs, check_program=False)       # open loop: same blocks, same sequences
    runner.next_setpoints(program.n_samples(fs) + 1)
    predictor = OnlinePredictor(choice)
    pairer = CyclePairer(min_amplitude=MIN_AMPLITUDE)
    out = []
    seq0 = int(r.sequence[0])
    for i in range(0, r.sequence.size, BATCH):
        sl = slice(i, i + BATCH)
        predicted, _ = predictor.process(int(r.sequence[i]), 1 / fs, r.displacement[sl])
        blocks = r.block_index[sl]
        cuts = np.flatnonzero(np.diff(blocks)) + 1
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, blocks.size], strict=True):
            for c in pairer.feed(int(r.sequence[i + a]), 1 / fs, r.displacement[sl][a:b], force[sl][a:b],
                                 predicted[a:b], int(blocks[a])):
                m = c.measured
                cyc = cycle_of(runner, c.start_sequence, c.end_sequence, m['amplitude'], m['peak_amplitude'],
                               m['mean'], cycle_properties(m), cycle_properties(c.model), c.residual_rms,
                               (c.end_sequence - seq0) / fs)
                if cyc is not None:
                    out.append(cyc)
    return out


REVERSAL_THRESHOLD = 2e-6    # [m] Berg reversal deadband of config/rig_sim.yaml (specimen and element_model)


def simulate(program, *, specimen: str = 'swing_arm_joint_20C', model: str = 'swing_arm_joint_20C',
             noise: float = 20.0, damage=(), faults=(), load_cell=None, seed: int = 0):
    """Run `program` on the unpaced simulated rig (amplitude control on) and return (RunResult, force, cycles).

    specimen/model: parameter sets of the simulated specimen and of the online model; noise: load-cell noise
    [N]; damage: DamageSpec mappings; faults: FaultSpec mappings of the simulated controller (e.g. a stuck
    load cell); load_cell: a LoadCellFault applied to the force record (its ``start`` counted from the first
    sample of the run). force is the force record the cycles were made from.
    """
    np.random.seed(seed)
    sim = {'specimen': {'parameter_set': specimen, 'friction_reversal_threshold': REVERSAL_THRESHOLD},
           'force_noise': noise, 'damage': [dict(d) for d in damage], 'faults': [dict(f) for f in faults],
           'seed': seed}
    r = run_program(program, {'paced': False, 'sample_rate': 1000.0, 'sim': sim}, amplitude_control=True)
    force = r.force if load_cell is None else load_cell.apply(r.time - r.time[0], r.force)
    choice = ModelChoice(parameter_set=model, friction_reversal_threshold=REVERSAL_THRESHOLD)
    return r, force, cycle_stream(r, program, choice, force)
