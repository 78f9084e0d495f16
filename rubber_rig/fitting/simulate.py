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

"""Simulated-rig recordings for fitting: run a program on the simulated rig and record it to MCAP.

Used by `rubber-rig simulate`, the fitting tests and benchmark (handy for trying `rubber-rig fit` without a
rig): the program runs on `rubber_rig.rig`'s simulated servo-hydraulic rig through the real CAN path, and the
samples are written by `rubber_rig.recording.RecordingWriter` exactly as the recorder node writes
them (RigSampleBatch on `samples`, SetpointBatch with the block index on `setpoints`, and the
`rubber_rig` metadata record: specimen, temperature, program, rig configuration).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from rubber_rig.excitation.program import Program, program_source
from rubber_rig.recording import RecordingWriter
from rubber_rig.session import run_program

SAMPLES_TOPIC = '/rubber_rig/samples'
SETPOINTS_TOPIC = '/rubber_rig/setpoints'


def _program_text(program) -> str:
    """YAML text of a program given as a shipped name, a path, YAML text or a mapping."""
    if isinstance(program, dict):
        return yaml.safe_dump(program, sort_keys=False)
    if isinstance(program, str) and '\n' in program:
        return program
    return program_source(program)[0]


def run_simulated(program, specimen: dict, temperature: float, *, force_noise=10.0, displacement_noise=0.2e-6,
                  sample_rate=1000.0, seed=0, sim_options: dict = None, config_options: dict = None):
    """Run `program` (name, path, YAML text or mapping) on the simulated rig, unpaced (as fast as it computes).

    sim_options: further SimOptions fields (e.g. force_delay, force_gain, force_offset); config_options: further
    top-level RigConfig fields (e.g. load_cell_delay, load_cell_gain). Returns (RunResult, program YAML text,
    rig configuration dict).
    """
    text = _program_text(program)
    prog = Program.from_yaml_text(text, name='program')
    sim = {'specimen': dict(specimen), 'force_noise': float(force_noise),
           'displacement_noise': float(displacement_noise), 'temperature': float(temperature), 'seed': int(seed)}
    sim.update(sim_options or {})
    config = {'backend': 'sim', 'paced': False, 'sample_rate': float(sample_rate)}
    config.update(config_options or {})
    config['sim'] = sim
    return run_program(prog, config), text, config


def write_recording(path, result, program_text: str, specimen: dict, temperature: float, config: dict = None,
                    batch: int = 100, channels=('displacement', 'force', 'setpoint'), metadata: dict = None):
    """Write a RunResult as an MCAP recording. `channels` chooses which sample arrays are real; a
    left-out channel is written as NaN (how a missing transducer shows up), for fault tests. `metadata`:
    further keys of the rubber_rig metadata record (they win over the ones written here, e.g. 'source').
    """
    path = Path(path)
    meta = {'specimen': dict(specimen), 'temperature': float(temperature), 'program': program_text,
            'rig_config': config or {}, 'source': 'rubber_rig.fitting.simulate'}
    meta.update(metadata or {})
    fs = float(result.sample_rate)
    period = 1.0 / fs
    n = len(result.time)
    t0_ns = 1_700_000_000_000_000_000
    seq0 = int(result.sequence[0]) if n else 0
    bi = np.asarray(result.block_index, int)
    arrays = {k: np.asarray(getattr(result, k), float) for k in ('displacement', 'force', 'setpoint')}
    for k in arrays:
        if k not in channels:
            arrays[k] = np.full(n, np.nan)
    # batches never straddle a block change, so each SetpointBatch carries one block index
    change = np.flatnonzero(np.diff(bi) != 0) + 1
    bounds = sorted(set(np.concatenate([[0], change, np.arange(0, n, batch), [n]]).tolist()))
    with RecordingWriter(path, meta, overwrite=True) as w:
        for a, b in zip(bounds[:-1], bounds[1:], strict=False):
            stamp_ns = t0_ns + int(round(a * period * 1e9))
            header = {'stamp': {'sec': stamp_ns // 1_000_000_000, 'nanosec': stamp_ns % 1_000_000_000},
                      'frame_id': 'rig'}
            seq = seq0 + a
            w.write_message(SETPOINTS_TOPIC, 'msg_defs/msg/SetpointBatch', {
                'header': header, 'first_sequence': seq, 'sample_period': period,
                'displacement': arrays['setpoint'][a:b].tolist(), 'block_index': int(bi[a])},
                log_time_ns=stamp_ns)
            w.write_message(SAMPLES_TOPIC, 'msg_defs/msg/RigSampleBatch', {
                'header': header, 'first_sequence': seq, 'sample_period': period,
                'displacement': arrays['displacement'][a:b].tolist(), 'force': arrays['force'][a:b].tolist(),
                'setpoint': arrays['setpoint'][a:b].tolist(), 'temperature': float(result.temperature[b - 1]),
                'status_flags': int(result.status[b - 1]), 'frames_lost': 0},
                log_time_ns=stamp_ns + int(round((b - a - 1) * period * 1e9)))
    return path


# what the simulated rig's sensors declare when they are said to be what they are (standard uncertainties 0)
EXACT_SENSORS = {'load_cell_gain_u': 0.0, 'load_cell_delay_u': 0.0, 'displacement_gain_u': 0.0, 'temperature_u': 0.0}


def simulated_recording(path, program, parameter_set: str, temperature: float, **kw):
    """Run `program` on the simulated rig with the specimen `parameter_set` and record it to `path`. The
    recording declares the simulated load cell's calibration as exactly known (gain 1, delay 0, standard
    uncertainties 0: it is what it is said to be) unless ``config_options`` say otherwise.
    """
    kw.setdefault('config_options', EXACT_SENSORS)
    specimen = {'model': 'fractional_zener_berg', 'parameter_set': parameter_set}
    result, text, config = run_simulated(program, specimen, temperature, **kw)
    if not result.completed:
        raise RuntimeError(f'simulated run did not complete: {result.message}')
    return write_recording(path, result, text, specimen, temperature, config)
