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

"""Excitation: waveforms, test programs (YAML), their pre-start check against the safe envelope, amplitude control.

Everything is generated from the sample index at a fixed rate, never from wall-clock time. Pure Python.
"""
from .blocks import Block, ProgramError
from .detector_specs import with_defaults
from .detectors import strongest
from .limits import check_program, element_force_model
from .program import PROGRAM_DIR, Program, load_program, program_source, read_program, shipped_programs
from .runner import BlockResult, ProgramRunner, Progress
from .waveform_types import TYPES, WAVEFORMS, WaveformType

__all__ = ['Block', 'BlockResult', 'PROGRAM_DIR', 'Program', 'ProgramError', 'ProgramRunner', 'Progress', 'TYPES',
           'WAVEFORMS', 'WaveformType', 'check_program', 'element_force_model', 'load_program', 'program_source',
           'read_program', 'shipped_programs', 'strongest', 'with_defaults']
