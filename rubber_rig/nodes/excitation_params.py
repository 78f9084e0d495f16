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

"""The excitation node's parameters: declared with their descriptions, ranges and units, checked together (a wrong
value fails the node's start, naming the parameter) and read into an :class:`ExcitationParams` the node holds.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import yaml
from rclpy.node import Node

from rubber_rig.excitation import read_program
from rubber_rig.excitation.detector_specs import DEFAULTS, DetectorError, parse_detectors
from rubber_rig.excitation.limits import element_force_model
from rubber_rig.nodes.params import ParameterError, declare
from rubber_rig.session.program_session import LEAD_TIME


@dataclass
class ExcitationParams:
    """The excitation node's parameters, as declared (units: s). ``default_detectors``: parsed DetectorSpecs;
    ``force_model``: the element force model of ``force_model_set`` (or None); ``program``: (Program, YAML text) of the
    ``program`` parameter, or None.
    """

    program_param: str
    amplitude_control: bool
    compensation_memory: bool
    lead_time: float
    batch_size: int
    stream_period: float
    feedback_period: float
    rig_driver: str
    status_timeout: float
    start_timeout: float
    require_recording: bool
    recorder_timeout: float
    force_model_set: str
    hold_timeout: float
    default_detectors: list
    force_model: object = None
    program: Optional[tuple] = None
    nice: int = 0


def declare_excitation_parameters(node: Node) -> ExcitationParams:
    """Declare the excitation's parameters on ``node``; their values, checked together (ParameterError names the
    one that is wrong).
    """
    program_param = declare(node, 'program', '', 'program (shipped name or YAML path) to run as soon as '
                            'the rig is ready; empty: wait for a run_program goal')
    amplitude_control = declare(node, 'amplitude_control', True, 'adjust command amplitude and mean '
                                'so the measured amplitude reaches the target (program parameter only)')
    compensation_memory = declare(node, 'compensation_memory', True, 'with amplitude control, each '
                                  'block starts from the gain and mean offset earlier blocks of the run '
                                  'learned (false: every block starts uncompensated)')
    lead_time = declare(node, 'lead_time', LEAD_TIME, 'how far ahead of the sample the rig plays (from when '
                        'its samples arrived) setpoints are streamed', range=(0.02, 5.0), units='s')
    batch_size = declare(node, 'batch_size', 50, 'setpoints per SetpointBatch', range=(1, 5000))
    stream_period = declare(node, 'stream_period', 0.04, 'period of the streaming timer',
                            range=(0.001, 0.5), units='s')
    feedback_period = declare(node, 'feedback_period', 0.2, 'period of action feedback',
                              range=(0.01, 10.0), units='s')
    rig_driver = declare(node, 'rig_driver', 'rig_driver', 'name of the rig_driver node whose '
                         'open_stream/stop_stream services this node calls (relative: same namespace)')
    status_timeout = declare(node, 'status_timeout', 0.8, 'neither a rig_driver status nor a sample batch '
                             'for this long ends a running program (the driver is gone)',
                             range=(0.2, 10.0), units='s')
    start_timeout = declare(node, 'start_timeout', 5.0, 'a goal waits up to this long for fresh rig and '
                            'recorder statuses and for DDS to match our topics (after a launch or a '
                            'node restart discovery can take seconds) before it is refused',
                            range=(0.0, 60.0), units='s')
    require_recording = declare(node, 'require_recording', False, 'start a program only while the '
                                "recorder reports recording this namespace's samples, and stop it if "
                                'the recording fails')
    recorder_timeout = declare(node, 'recorder_timeout', 2.0, 'with require_recording: a recorder status '
                               'older than this stops a running program (the recorder publishes it every '
                               '0.5 s)', range=(0.5, 60.0), units='s')
    force_model_set = declare(node, 'force_model', 'swing_arm_joint_20C', 'element-model parameter set that '
                              'predicts each block\'s peak force before start (refused above '
                              "limits.force_max); '' = no force prediction")
    hold_timeout = declare(node, 'hold_timeout', 600.0, 'a program held (operator or detector) this long '
                           'without a resume ends: the rig ramps to the rest position and the goal says why',
                           range=(1.0, 86400.0), units='s')
    default_detectors = declare(node, 'default_detectors', 'default', "detectors every program runs with "
                                "besides its own (a program's detector of the same name replaces one): "
                                "'default' (residual, stiffness_change, force_drift, tracking; README "
                                "'Detectors'), '' for none, or a YAML list like [{type: residual, threshold: 5}]")
    try:
        raw = list(DEFAULTS) if default_detectors == 'default' else yaml.safe_load(default_detectors) or []
        detectors = parse_detectors(raw, 'default_detectors')
    except (DetectorError, yaml.YAMLError) as exc:
        raise ParameterError(node, 'default_detectors', str(exc)) from None
    nice = declare(node, 'nice', 0, 'niceness of the excitation process, set when it starts as a process of its own '
                   '(rubber_rig.rig.priority): below 0 its setpoint stream gets the CPU before the other programs of '
                   'this computer, so a busy computer delays the stream less than lead_time; needs root or '
                   'CAP_SYS_NICE, else a warning and the process keeps its priority', range=(-20, 19))
    if stream_period >= lead_time / 2:
        raise ParameterError(node, 'stream_period', f'{stream_period} s must be below half '
                             f'of lead_time ({lead_time} s) or the driver could starve')
    try:
        force_model = element_force_model(force_model_set) if force_model_set else None
    except (ValueError, OSError) as exc:
        raise ParameterError(node, 'force_model', str(exc)) from None
    program = None
    if program_param:  # validate at start: a wrong name fails here, naming the parameter
        try:
            program = read_program(program_param)
        except (ValueError, OSError) as exc:
            raise ParameterError(node, 'program', str(exc)) from None
    return ExcitationParams(program_param, amplitude_control, compensation_memory, lead_time, batch_size, stream_period,
                            feedback_period, rig_driver, status_timeout, start_timeout, require_recording,
                            recorder_timeout, force_model_set, hold_timeout, detectors, force_model, program, nice)
