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

"""Recordings as plain arrays for fitting, from MCAP files (rubber_rig.recording), rig runs or arrays.

Channel problems are reported, not raised, whenever something is still usable:
- no force channel: the recording cannot be fitted (message, recording skipped);
- no displacement channel: the setpoint is used instead, with a warning (it lacks the actuator's
  amplitude and phase error, so stiffness and damping are biased at high frequency);
- the temperature: the channel's median when there is one, else the metadata's; both are kept and compared
  (fitting.temperature: a disagreement is a warning naming both).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from rubber_rig.excitation.program import Program
from rubber_rig.models import load_parameter_set
from rubber_rig.recording import RecordingError, load_recording

from .events import recorded_cycles, recorded_events
from .temperature import resolve as resolve_temperature


@dataclass
class RunData:
    name: str
    dt: float
    displacement: np.ndarray | None
    force: np.ndarray | None
    setpoint: np.ndarray | None = None
    temperature: float | None = None           # specimen temperature [degC] of the run
    block_index: np.ndarray | None = None
    program_blocks: list | None = None         # [{'frequency': Hz, 'amplitude': m, ...}] in program order
    metadata: dict = field(default_factory=dict)
    messages: list = field(default_factory=list)
    true_params: dict | None = None            # specimen parameters when the run is simulated
    cycles: dict | None = None                 # the element model's per-cycle metrics (fitting.events)
    events: list = field(default_factory=list)  # detector events (fitting.events)
    # the temperature's three statements (fitting.temperature.resolve compares them; ``temperature`` is its choice)
    temperature_metadata: float | None = None  # what the metadata says [degC]
    temperature_channel: np.ndarray | None = None   # the recorded temperature channel [degC], per sample
    temperature_override: float | None = None  # given by the user (rubber-rig fit --temperature) [degC]
    temperature_record: dict | None = None     # fitting.temperature.resolve's result

    def usable(self) -> bool:
        return self.force is not None and self.displacement is not None


def _arr(v):
    if v is None:
        return None
    a = np.asarray(v, float)
    if not a.size or not np.isfinite(a).any():
        return None          # an absent transducer: no samples, or only NaN
    return a


def _program_blocks(program):
    """Blocks of a program (Program object, mapping or YAML text) as dicts in SI, in run order.

    Mappings and text go through `rubber_rig.excitation`'s parser, so grids and unit suffixes
    expand exactly as the rig ran them.
    """
    if program is None:
        return None
    if isinstance(program, (str, dict)):
        try:
            program = (Program.from_yaml_text(program) if isinstance(program, str)
                       else Program.from_dict(program))
        except Exception:   # noqa: BLE001 - without a readable program the blocks are detected
            return None
    blocks = getattr(program, 'blocks', None)
    if blocks is None and isinstance(program, (list, tuple)):
        blocks = program
    if blocks is None:
        return None
    out = []
    for b in blocks:
        get = b.get if isinstance(b, dict) else (lambda k, d=None, b=b: getattr(b, k, d))
        out.append({'frequency': _num(get('frequency')), 'amplitude': _num(get('amplitude')),
                    'waveform': get('waveform', 'sine'), 'cycles': get('cycles'),
                    'taper_cycles': get('taper_cycles'), 'mean': _num(get('mean')),
                    'name': get('name', '')})
    return out


def _num(v):
    if v is None:
        return None
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def _finish(run: RunData) -> RunData:
    if run.temperature_metadata is None:
        run.temperature_metadata = run.temperature      # from_arrays(temperature=...): a stated temperature
    run.temperature_record = resolve_temperature(run.temperature_metadata, run.temperature_channel,
                                                 metadata_u=_num((run.metadata or {}).get('temperature_u')),
                                                 override=run.temperature_override)
    run.temperature = run.temperature_record['value']
    if run.force is None:
        run.messages.append(f'{run.name}: no force channel; this recording cannot be fitted')
    if run.displacement is None:
        if run.setpoint is not None:
            run.displacement = run.setpoint
            run.messages.append(f'{run.name}: no measured displacement channel; using the setpoint instead '
                                '(actuator amplitude/phase errors are not seen, so K_dyn and C_eq are biased '
                                'at high frequency)')
        else:
            run.messages.append(f'{run.name}: no displacement or setpoint channel; this recording cannot be fitted')
    if run.block_index is not None and not (np.asarray(run.block_index) >= 0).any():
        run.block_index = None   # e.g. `ros2 bag record` without the setpoint topic: all -1
        run.messages.append(f'{run.name}: no block index recorded; blocks are detected as steady '
                            'periodic segments')
    if run.force is not None and run.displacement is not None:
        n = min(run.force.size, run.displacement.size)
        if run.force.size != run.displacement.size:
            run.messages.append(f'{run.name}: force and displacement differ in length; using the first {n} samples')
        run.force, run.displacement = run.force[:n], run.displacement[:n]
        if run.block_index is not None:
            run.block_index = run.block_index[:n]
    return run


def with_temperature(run: RunData, sensor_u=None, override=None) -> RunData:
    """A copy of ``run`` whose temperature is resolved again (fitting.temperature.resolve) with the temperature
    sensor's declared standard uncertainty ``sensor_u`` [K] and a user's ``override`` [degC] (None: keep the
    run's own override).
    """
    out = copy.copy(run)
    if override is not None:
        out.temperature_override = float(override)
    out.temperature_record = resolve_temperature(out.temperature_metadata, out.temperature_channel, sensor_u=sensor_u,
                                                 metadata_u=_num((out.metadata or {}).get('temperature_u')),
                                                 override=out.temperature_override)
    out.temperature = out.temperature_record['value']
    return out


def from_arrays(name, dt, displacement, force, **kw) -> RunData:
    return _finish(RunData(name=name, dt=float(dt), displacement=_arr(displacement), force=_arr(force), **kw))


def load_run(path) -> RunData:
    """Read an MCAP recording with rubber_rig.recording and keep what fitting needs."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f'no such recording: {path}')
    messages = []
    try:
        rec = load_recording(str(path))
    except RecordingError as exc:
        if 'truncated' not in str(exc):
            raise
        # the writer was killed or the disk filled: fit what was written before the cut
        rec = load_recording(str(path), allow_truncated=True)
        messages.append(f'{path.name}: truncated recording (no MCAP summary); using the '
                        f'{len(rec.force) if rec.force is not None else 0} samples written before the cut')
    signals = getattr(rec, 'signals', None) or {}

    def sig(name):
        v = getattr(rec, name, None)
        if v is None and isinstance(signals, dict):
            v = signals.get(name)
        return _arr(v)

    time = sig('time')
    meta = dict(getattr(rec, 'metadata', {}) or {})
    dt = None
    period = getattr(rec, 'sample_period', None)
    if period is not None and np.isfinite(period) and period > 0:
        dt = float(period)
    elif time is not None and time.size > 1:
        dt = float(np.median(np.diff(time)))
    if dt is None:
        rate = meta.get('sample_rate') or meta.get('rate')
        if rate:
            dt = 1.0 / float(rate)
    if dt is None:
        raise ValueError(f'{path.name}: no time channel and no sample rate in the metadata')
    temp_ch = sig('temperature')
    temperature = _meta_temperature(meta)
    if temp_ch is None:
        messages.append(f'{path.name}: no temperature channel; using the metadata temperature '
                        f'({temperature if temperature is not None else "unknown"})')
    bi = sig('block_index')
    run = RunData(name=path.name, dt=dt, displacement=sig('displacement'), force=sig('force'),
                  setpoint=sig('setpoint'), temperature=temperature, temperature_metadata=temperature,
                  temperature_channel=temp_ch, block_index=None if bi is None else bi.astype(int),
                  program_blocks=_program_blocks(_meta_program(meta)), metadata=meta,
                  messages=messages, true_params=_meta_true_params(meta), cycles=recorded_cycles(rec),
                  events=recorded_events(rec))
    return _finish(run)


def _meta_temperature(meta):
    for key in ('temperature', 'specimen_temperature'):
        v = meta.get(key)
        if isinstance(v, dict):
            v = v.get('value', v.get('temperature'))
        if v is not None:
            try:
                return float(v)
            except (TypeError, ValueError):
                pass
    spec = meta.get('specimen')
    if isinstance(spec, dict) and spec.get('temperature') is not None:
        return float(spec['temperature'])
    return None


def _meta_program(meta):
    return meta.get('program') or meta.get('test_program')


def _meta_true_params(meta):
    spec = meta.get('specimen')
    if isinstance(spec, str):
        try:
            spec = yaml.safe_load(spec)
        except yaml.YAMLError:
            return None
    if isinstance(spec, dict):
        p = spec.get('parameters') or spec.get('params')
        if isinstance(p, dict):
            return p
        name = spec.get('parameter_set')
        if name:
            try:
                return load_parameter_set(name).as_dict()
            except Exception:   # noqa: BLE001 - only used to print the truth next to the fit
                return None
    return None
