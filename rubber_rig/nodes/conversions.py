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

"""msg_defs <-> core conversions shared by the nodes (the only place that knows both sides).

Everything is SI on both sides. Arrays go into messages as float64 sequences; rosidl-generated Python
messages accept numpy arrays directly (``array.array('d')`` underneath), which keeps 1-10 kHz batches cheap.
"""
from __future__ import annotations

import array
import math
from typing import Any, Iterable, Mapping

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from msg_defs.msg import (
    BlockSummary,
    BranchForce,
    CycleMetrics,
    CycleProperties,
    DetectorEvent,
    ModelParameters,
    ModelPrediction,
    RigLimits,
    RigSampleBatch,
    RigStatus,
    SetpointBatch,
)
from rubber_rig.online import PROPERTY_FIELDS, cycle_properties
from rubber_rig.rig.can.protocol import STATE_CODE, STATES, fault_names
from rubber_rig.safety import Limits

# RigStatus.STATE_* and FAULT_* equal the DBC's codes (test_rig_protocol checks it): one table serves both
STATE_NAMES = dict(enumerate(STATES))
STATE_BY_NAME = STATE_CODE


# -- time --------------------------------------------------------------------------------------------------
def stamp(t: float) -> Time:
    """Seconds (float) -> builtin_interfaces/Time."""
    sec = math.floor(t)
    return Time(sec=int(sec), nanosec=min(int(round((t - sec) * 1e9)), 999_999_999))


def to_seconds(t: Time) -> float:
    return t.sec + t.nanosec * 1e-9


def f64(values) -> array.array:
    """Any float sequence -> array.array('d'): the setter of a rosidl float64[] field takes it without a
    per-element Python check (about 10x cheaper than assigning a numpy array directly).
    """
    out = array.array('d')
    out.frombytes(np.ascontiguousarray(values, dtype=np.float64).tobytes())
    return out


def as_array(seq) -> np.ndarray:
    """A float64[] field (array.array) -> numpy view without copying."""
    return np.frombuffer(seq, dtype=np.float64) if len(seq) else np.zeros(0)


def _get(obj: Any, name: str, default=None):
    """Read a field from a dataclass-like object or a mapping (the core returns either)."""
    if isinstance(obj, Mapping):
        return obj.get(name, default)
    return getattr(obj, name, default)


# -- samples and setpoints ------------------------------------------------------------------------------------
def last_sample_time(msg: RigSampleBatch) -> float:
    """When the last sample of a msg_defs/RigSampleBatch was measured [s] (its stamp is the first sample's)."""
    return to_seconds(msg.header.stamp) + max(len(msg.displacement) - 1, 0) * msg.sample_period


def sample_batch_msg(first_sequence: int, t0: float, sample_period: float, displacement, force, setpoint,
                     temperature: float, status_flags: int, frames_lost: int) -> RigSampleBatch:
    msg = RigSampleBatch()
    msg.header.stamp = stamp(t0)
    msg.first_sequence = int(first_sequence)
    msg.sample_period = float(sample_period)
    msg.displacement = f64(displacement)
    msg.force = f64(force)
    msg.setpoint = f64(setpoint)
    msg.temperature = float(temperature)
    msg.status_flags = int(status_flags)
    msg.frames_lost = int(frames_lost)
    return msg


def batch_arrays(msg: RigSampleBatch) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(displacement, force, setpoint) of a RigSampleBatch as numpy arrays (zero-copy where possible)."""
    return as_array(msg.displacement), as_array(msg.force), as_array(msg.setpoint)


def setpoint_batch_msg(first_sequence: int, sample_period: float, displacement, block_index: int,
                       t: float | None = None, stream_id: int = 0, source: str = '',
                       end_of_stream: bool = False) -> SetpointBatch:
    msg = SetpointBatch()
    if t is not None:
        msg.header.stamp = stamp(t)
    msg.stream_id, msg.source, msg.end_of_stream = int(stream_id), str(source), bool(end_of_stream)
    msg.first_sequence = int(first_sequence)
    msg.sample_period = float(sample_period)
    msg.displacement = f64(displacement)
    msg.block_index = int(block_index)
    return msg


# -- status and diagnostics -----------------------------------------------------------------------------------
def limits_msg(limits: Any) -> RigLimits:
    msg = RigLimits()
    for name in ('displacement_min', 'displacement_max', 'velocity_max', 'force_max', 'deceleration_max'):
        value = _get(limits, name)
        if value is not None:
            setattr(msg, name, float(value))
    return msg


def limits_from_msg(msg: RigLimits):
    """rubber_rig.excitation.Limits from a msg_defs/RigLimits (the inverse of limits_msg)."""
    return Limits(displacement_min=msg.displacement_min, displacement_max=msg.displacement_max,
                  velocity_max=msg.velocity_max, force_max=msg.force_max,
                  deceleration_max=msg.deceleration_max or Limits.deceleration_max)


def state_code(state: Any) -> int:
    """Core state (int, enum or name) -> RigStatus.STATE_*."""
    if isinstance(state, str):
        return STATE_BY_NAME.get(state.lower(), RigStatus.STATE_FAULT)
    name = getattr(state, 'name', None)
    if isinstance(name, str) and name.lower() in STATE_BY_NAME:
        return STATE_BY_NAME[name.lower()]
    return int(getattr(state, 'value', state))


def status_msg(snapshot: Any, limits: Any, sample_rate: float, t: float) -> RigStatus:
    """A driver status snapshot (fields as in RigStatus) -> RigStatus."""
    msg = RigStatus()
    msg.header.stamp = stamp(t)
    msg.state = state_code(_get(snapshot, 'state', RigStatus.STATE_UNCONFIGURED))
    msg.state_name = STATE_NAMES.get(msg.state, 'unknown')
    msg.faults = int(_get(snapshot, 'faults', 0) or 0)
    msg.fault_messages = [str(m) for m in (_get(snapshot, 'messages', None)
                                           or _get(snapshot, 'fault_messages', None) or [])]
    msg.limits = limits_msg(limits)
    msg.sample_rate = float(sample_rate)
    counters = _get(snapshot, 'counters', None) or {}
    for name in ('samples_received', 'frames_lost', 'frames_late', 'frames_malformed', 'frames_unknown'):
        value = _get(snapshot, name, None)
        if value is None:
            value = _get(counters, name, 0)
        setattr(msg, name, int(value or 0))
    temperature = _get(snapshot, 'temperature', None)
    msg.temperature = float('nan') if temperature is None else float(temperature)
    extra = _get(snapshot, 'extra', None) or {}
    msg.next_sequence = int(extra.get('next_sequence', 0))
    msg.last_sample = int(_get(snapshot, 'controller_sequence', -1))
    msg.position = float(extra.get('position', 0.0))
    measured = extra.get('bus_load_measured')
    msg.bus_load = float(measured if measured is not None else extra.get('bus_load', math.nan))
    msg.stream_owner = str(extra.get('stream_owner', ''))
    msg.stream_id = int(extra.get('stream_id', 0))
    msg.setpoints_refused = int(extra.get('setpoints_refused', 0))
    msg.last_event = str(extra.get('last_event', ''))
    return msg


def bus_lines(driver: Any, frame_profile: str) -> dict:
    """The bus's lines of rig_driver's /diagnostics: the load the protocol needs at this rate (worst-case stuffing),
    the load measured on the simulated bus (when it has bit timing) and the frame profile.
    """
    lines = {'bus_load_pct': f'{driver.bus_load * 100:.1f}', 'can_profile': frame_profile}
    measured = driver.status.extra['bus_load_measured']
    if measured is not None:
        lines['bus_load_measured_pct'] = f'{measured * 100:.1f}'
    return lines


def diagnostics_msg(status: RigStatus, hardware_id: str, extra: Mapping[str, Any] | None = None,
                    name: str = 'rig_driver') -> DiagnosticArray:
    """RigStatus -> diagnostic_msgs/DiagnosticArray (OK running/idle, WARN frame loss, ERROR fault)."""
    d = DiagnosticStatus()
    d.name = name
    d.hardware_id = hardware_id
    if status.state == RigStatus.STATE_FAULT or status.faults:
        d.level = DiagnosticStatus.ERROR
        # the fault's own words (who went silent, which limit, ...) where an operator looks: rqt_robot_monitor and
        # Foxglove show the message; the names alone ('stream') do not say what to do
        d.message = 'fault: ' + ', '.join(fault_names(status.faults) or ['unknown']) + (
            ': ' + '; '.join(status.fault_messages[-3:]) if status.fault_messages else '')
    elif status.frames_lost or status.frames_malformed:
        d.level = DiagnosticStatus.WARN
        d.message = f'{status.state_name}; {status.frames_lost} frames lost, {status.frames_malformed} malformed'
    elif status.setpoints_refused:
        d.level = DiagnosticStatus.WARN
        d.message = f'{status.state_name}; {status.setpoints_refused} setpoints refused (foreign or broken stream)'
    else:
        d.level = DiagnosticStatus.OK
        d.message = status.state_name
    values = {'state': status.state_name, 'faults': status.faults, 'sample_rate': status.sample_rate,
              'samples_received': status.samples_received, 'frames_lost': status.frames_lost,
              'frames_late': status.frames_late, 'frames_malformed': status.frames_malformed,
              'frames_unknown': status.frames_unknown, 'temperature': status.temperature,
              'stream_owner': status.stream_owner, 'setpoints_refused': status.setpoints_refused,
              'position_m': status.position, 'last_event': status.last_event,
              'fault_messages': '; '.join(status.fault_messages)}
    values.update(extra or {})
    d.values = [KeyValue(key=str(k), value=str(v)) for k, v in values.items()]
    arr = DiagnosticArray()
    arr.header.stamp = status.header.stamp
    arr.status = [d]
    return arr


# -- element model -------------------------------------------------------------------------------------------------
def prediction_msg(batch: RigSampleBatch, predicted, branch_names: Iterable[str] = (),
                   branches=None) -> ModelPrediction:
    msg = ModelPrediction()
    msg.header = batch.header
    msg.first_sequence = batch.first_sequence
    msg.sample_period = batch.sample_period
    f = as_array(batch.force)
    predicted = np.asarray(predicted, dtype=np.float64)
    msg.displacement = batch.displacement  # already array.array('d'): no copy through numpy
    msg.measured_force = batch.force
    msg.predicted_force = f64(predicted)
    msg.residual = f64(f - predicted)
    if branches is not None:
        msg.branches = [BranchForce(name=str(n), force=f64(b))
                        for n, b in zip(branch_names, branches, strict=False)]
    return msg


def cycle_properties_msg(m: Any) -> CycleProperties:
    msg = CycleProperties()
    for name, value in cycle_properties(m).items():
        setattr(msg, name, value)
    return msg


def cycle_properties_dict(msg: CycleProperties) -> dict:
    """msg_defs/CycleProperties -> {field: value} (SI), what rubber_rig.excitation.detectors judges."""
    return {name: float(getattr(msg, name)) for name in PROPERTY_FIELDS}


def detector_event_dict(msg: DetectorEvent) -> dict:
    """msg_defs/DetectorEvent -> {field: value} of every field but the header (SI, as on the message)."""
    return {k: getattr(msg, k) for k in msg.get_fields_and_field_types() if k != 'header'}


def cycle_metrics_msg(measured: Any, model: Any, block_index: int, cycle_index: int, t: float,
                      start_sequence: int = 0, end_sequence: int = 0,
                      residual_rms: float = float('nan')) -> CycleMetrics:
    msg = CycleMetrics()
    msg.header.stamp = stamp(t)
    msg.block_index = int(block_index)
    msg.cycle_index = int(cycle_index)
    msg.start_sequence, msg.end_sequence = int(start_sequence), int(end_sequence)
    msg.residual_rms = float(residual_rms)
    msg.frequency = float(_get(measured, 'frequency', float('nan')))
    msg.amplitude = float(_get(measured, 'amplitude', float('nan')))
    msg.peak_amplitude = float(_get(measured, 'peak_amplitude', float('nan')))
    msg.mean = float(_get(measured, 'mean', float('nan')))
    msg.measured = cycle_properties_msg(measured)
    msg.model = cycle_properties_msg(model)
    return msg


def model_parameters_msg(model_name: str, parameter_set: str, temperature: float,
                         values: Mapping[str, float], t: float) -> ModelParameters:
    msg = ModelParameters()
    msg.header.stamp = stamp(t)
    msg.model_name = model_name
    msg.parameter_set = parameter_set
    msg.temperature = float(temperature)
    msg.names = [str(k) for k in values]
    msg.values = [float(v) for v in values.values()]
    return msg


def block_summary_msg(s: Any, index: int | None = None) -> BlockSummary:
    msg = BlockSummary()
    msg.block_index = int(_get(s, 'block_index', index if index is not None else -1))
    msg.name = str(_get(s, 'name', '') or '')
    msg.waveform = str(_get(s, 'waveform', '') or '')
    for name in ('frequency', 'target_amplitude', 'achieved_amplitude', 'mean'):
        value = _get(s, name)
        setattr(msg, name, float('nan') if value is None else float(value))
    msg.cycles = int(_get(s, 'cycles', 0) or 0)
    msg.completed = bool(_get(s, 'completed', False))
    msg.message = str(_get(s, 'message', '') or '')
    return msg


def detector_event_msg(event: Any, program: str, block_name: str, t: float) -> DetectorEvent:
    """rubber_rig.excitation.detectors.Event -> msg_defs/DetectorEvent (stamped t [s])."""
    msg = DetectorEvent()
    msg.header.stamp = stamp(t)
    msg.program, msg.block_name = str(program), str(block_name)
    msg.detector, msg.kind, msg.action = event.detector, event.kind, event.action
    msg.block_index, msg.cycle, msg.program_cycle = int(event.block), int(event.cycle), int(event.program_cycle)
    msg.elapsed, msg.value, msg.sequence = float(event.elapsed), float(event.value), int(event.sequence)
    msg.reference, msg.threshold = float(event.reference), float(event.threshold)
    msg.units, msg.message = event.units, event.message
    msg.cause, msg.code = str(getattr(event, 'cause', '') or ''), str(getattr(event, 'code', '') or '')
    return msg
