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


"""Run a test program on the simulated rig, without ROS and faster than real time, and record it to MCAP.

Examples:
  rubber-rig simulate --model specimen.yaml --program preload_sine_grid -o run.mcap
  rubber-rig simulate --model zener_berg --program my_program.yaml --load-cell-delay 0.2ms -o run.mcap
The recording has the bench's format (RigSampleBatch, SetpointBatch with block index, rubber_rig
metadata), so `rubber-rig fit`, `report` and `info` read it like a bench run. The model (a model file
with "elements", a named model or a parameter set, see `rubber-rig fit --model`) is written inline
into the metadata ('specimen': the model file's mapping in SI) so a fit can be compared with the truth.
--load-cell-delay/--load-cell-gain/--force-offset/--force-drift make the simulated load cell imperfect (it reads
gain x the force of delay s earlier + offset + drift x t + noise; rig_config.sim.force_* in the metadata); with
--record-calibration they are also recorded as the lab's known calibration (rig_config.load_cell_delay
and load_cell_gain), which `rubber-rig fit` then corrects for. Values take unit suffixes (0.2ms, 2N).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

from rubber_rig.rig.config import RigConfig
from rubber_rig.settings import described
from rubber_rig.units import to_si

from .main import CommandError

RATE_RANGE = described(RigConfig, 'sample_rate').range   # rig sample rate [Hz]
TEMPERATURE_RANGE = (-60.0, 150.0)      # [degC] (SimOptions.temperature)
FORCE_NOISE_RANGE = (0.0, 1e4)          # [N]
DISPLACEMENT_NOISE_RANGE = (0.0, 1e-3)  # [m]
DELAY_RANGE = (0.0, 0.1)                # [s] (SimOptions.force_delay)
GAIN_RANGE = (0.01, 100.0)              # [-] (SimOptions.force_gain)
OFFSET_RANGE = (-1e5, 1e5)              # [N] (SimOptions.force_offset)
DRIFT_RANGE = (-1e3, 1e3)                # [N/s] (SimOptions.force_drift)
SEED_RANGE = (0, 2**31 - 1)


def add_arguments(parser):
    parser.add_argument('--model', '-m', required=True,
                        help='specimen: a model file (.yaml with "elements"), a named model (zener_berg, '
                             'zener_berg_cubic, seed003, pad, ...) or a parameter set (swing_arm_joint_20C)')
    parser.add_argument('--program', '-p', required=True,
                        help='test program: a shipped name (dynamic_stiffness_grid, quasi_static_then_sine, '
                             'log_sweeps_1_50hz, preload_sine_grid, durability_10hz) or a program YAML file')
    parser.add_argument('--output', '-o', required=True, help='MCAP recording to write (replaced if it exists)')
    parser.add_argument('--temperature', '-T', default=None,
                        help="specimen temperature [degC] recorded (metadata and temperature channel; the model's "
                             "values do not change with it); default: the model's temperature, else 20")
    parser.add_argument('--rate', default='1kHz', help='sample rate (default 1kHz)')
    parser.add_argument('--force-noise', default='2N', help='load cell noise, standard deviation (default 2N)')
    parser.add_argument('--displacement-noise', default='0.2um',
                        help='displacement transducer noise, standard deviation (default 0.2um)')
    parser.add_argument('--load-cell-delay', default='0s',
                        help='the load cell reads the force of this long ago (default 0s; at most 0.1s)')
    parser.add_argument('--load-cell-gain', default='1', help='the load cell reads gain x the force (default 1)')
    parser.add_argument('--force-offset', default='0N', help='load cell offset (default 0N)')
    parser.add_argument('--force-drift', default='0N/s', help='load cell zero drift: the offset grows by this '
                        'much per second (default 0N/s)')
    parser.add_argument('--record-calibration', action='store_true',
                        help='also record the load-cell delay and gain as known calibration (rig_config.'
                             'load_cell_delay/load_cell_gain), which rubber-rig fit applies, known exactly '
                             '(load_cell_delay_u/load_cell_gain_u, displacement_gain_u and temperature_u 0: the '
                             'simulated sensors are what they are said to be); without it the recording declares '
                             'no calibration and the fit says so')
    parser.add_argument('--seed', type=int, default=0, help='random seed of the simulated sensors (default 0)')


def _quantity(option, text, dimension, allowed, unit):
    """`text` (number or unit suffix) in SI, inside `allowed`; ValueError naming the option otherwise."""
    try:
        value = to_si(text, dimension)
    except ValueError as exc:
        raise ValueError(f'{option}: {exc}') from None
    lo, hi = allowed
    if not lo <= value <= hi:
        given = f'{value:g} {unit}'.rstrip()
        if str(text) != f'{value:g}':
            given = f'{text} (= {given})'
        raise ValueError(f'{option} {given} is outside the allowed range {lo:g} .. {hi:g} {unit}'.rstrip())
    return value


def resolve_specimen(source):
    """The ModelSpec of --model; errors name the model file or the name (ValueError)."""
    from rubber_rig.models.modelfile import load_model_file, resolve_model
    path = Path(str(source)).expanduser()
    try:
        # an existing file is read as a model file, so its own problem is named (not "unknown model")
        return load_model_file(path) if path.is_file() else resolve_model(source)
    except FileNotFoundError as exc:
        raise ValueError(f'--model: {exc}') from None
    except ValueError as exc:
        raise ValueError(f'--model {source}: {exc}' if str(source) not in str(exc) else f'--model: {exc}') from None


def program_text(source) -> str:
    """The YAML text of --program (shipped name or file), validated; errors name the program."""
    from rubber_rig.excitation.program import Program, program_source
    try:
        text, name = program_source(source)
    except FileNotFoundError as exc:
        raise ValueError(f'--program: {exc}') from None
    except OSError as exc:
        raise ValueError(f'--program {source}: cannot be read ({exc.strerror or exc})') from None
    try:
        Program.from_yaml_text(text, name=name)
    except ValueError as exc:
        raise ValueError(f'--program {source}: {exc}') from None
    return text


def run(args) -> int:
    from rubber_rig.fitting.simulate import EXACT_SENSORS, run_simulated, write_recording
    from rubber_rig.recording import RecordingWriteError

    rate = _quantity('--rate', args.rate, 'frequency', RATE_RANGE, 'Hz')
    force_noise = _quantity('--force-noise', args.force_noise, 'force', FORCE_NOISE_RANGE, 'N')
    disp_noise = _quantity('--displacement-noise', args.displacement_noise, 'length', DISPLACEMENT_NOISE_RANGE, 'm')
    delay = _quantity('--load-cell-delay', args.load_cell_delay, 'time', DELAY_RANGE, 's')
    gain = _quantity('--load-cell-gain', args.load_cell_gain, 'number', GAIN_RANGE, '')
    offset = _quantity('--force-offset', args.force_offset, 'force', OFFSET_RANGE, 'N')
    drift = _quantity('--force-drift', args.force_drift, 'force_rate', DRIFT_RANGE, 'N/s')
    if not SEED_RANGE[0] <= args.seed <= SEED_RANGE[1]:
        raise ValueError(f'--seed {args.seed} is outside the allowed range {SEED_RANGE[0]} .. {SEED_RANGE[1]}')
    spec = resolve_specimen(args.model)
    model_temperature = spec.meta.get('temperature')
    if args.temperature is not None:
        temperature = _quantity('--temperature', args.temperature, 'temperature', TEMPERATURE_RANGE, 'degC')
    else:
        temperature = float(model_temperature) if model_temperature is not None else 20.0
        if not TEMPERATURE_RANGE[0] <= temperature <= TEMPERATURE_RANGE[1]:
            raise ValueError(f'--model {args.model}: temperature {temperature:g} degC outside '
                             f'{TEMPERATURE_RANGE[0]:g} .. {TEMPERATURE_RANGE[1]:g} degC (give --temperature)')
    text = program_text(args.program)
    out_dir = Path(args.output).expanduser().resolve().parent
    if not out_dir.is_dir():   # before the run, not after it
        raise CommandError(f'cannot create recording {args.output}: no directory {out_dir}')

    # the truth, self-contained: the model file's mapping (SI) at the temperature of the run
    specimen = spec.to_dict()
    specimen['temperature'] = temperature
    if model_temperature is not None and not math.isclose(float(model_temperature), temperature, abs_tol=1e-9):
        print(f"rubber-rig simulate: note: the model's values are for {float(model_temperature):g} degC; they are "
              f'simulated unchanged and recorded as {temperature:g} degC', file=sys.stderr)
    load_cell = {'force_delay': delay, 'force_gain': gain, 'force_offset': offset, 'force_drift': drift}
    calibration = {'load_cell_delay': delay, 'load_cell_gain': gain, **EXACT_SENSORS} if args.record_calibration \
        else {}
    result, text, config = run_simulated(text, specimen, temperature, force_noise=force_noise,
                                         displacement_noise=disp_noise, sample_rate=rate, seed=args.seed,
                                         sim_options=load_cell, config_options=calibration)
    meta = {'source': 'rubber-rig simulate', 'model': spec.name,
            'simulated_load_cell': {'delay': delay, 'gain': gain, 'offset': offset, 'drift': drift,
                                    'noise': force_noise}}
    try:
        path = write_recording(args.output, result, text, specimen, temperature, config, metadata=meta)
    except RecordingWriteError as exc:     # the output cannot be written: the inputs are fine, the job failed
        raise CommandError(str(exc)) from None
    n = len(result.time)
    duration = n / result.sample_rate
    blocks = len(result.blocks)
    speed = f', {duration / result.wall_time:.0f}x real time' if result.wall_time > 0 else ''
    print(f'{n} samples, {duration:.3f} s at {result.sample_rate:g} Hz, {blocks} blocks, {result.wall_time:.2f} s '
          f'wall{speed} -> {path}')
    if not result.completed:
        raise CommandError(f'the simulated run did not complete: {result.message} ({path} holds the samples '
                           'up to there)')
    return 0
