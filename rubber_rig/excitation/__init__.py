"""Excitation: waveforms, test programs (YAML), limits, amplitude control and the abort ramp.

Everything is generated from the sample index at a fixed rate, never from wall-clock time. Pure Python.
"""
from .blocks import Block, ProgramError
from .limits import LimitError, Limits
from .program import PROGRAM_DIR, Program, load_program, program_source, read_program, shipped_programs
from .ramp import SafeRamp
from .runner import BlockResult, ProgramRunner, Progress
from .waveforms import WAVEFORMS

__all__ = ['Block', 'BlockResult', 'LimitError', 'Limits', 'PROGRAM_DIR', 'Program', 'ProgramError',
           'ProgramRunner', 'Progress', 'SafeRamp', 'WAVEFORMS', 'load_program', 'program_source', 'read_program',
           'shipped_programs']
