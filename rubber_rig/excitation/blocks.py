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

"""One program block: its fields (SI), validation with errors naming block and field, and evaluation."""
import math
from dataclasses import dataclass, field

import numpy as np

from rubber_rig.units import to_si

from . import waveforms as wf
from .detector_specs import DetectorError, parse_detectors
from .waveform_types import ALIASES, TYPES, WAVEFORMS, WaveformType


class ProgramError(ValueError):
    """A test program is invalid; the message names the block (index and name) and the field."""


# field -> dimension of its value (None: plain number / text); the allowed fields per waveform follow
_FIELDS = {
    'name': None, 'waveform': None, 'frequency': 'frequency', 'f_start': 'frequency', 'f_end': 'frequency',
    'amplitude': 'length', 'mean': 'length', 'cycles': None, 'taper_cycles': None, 'duration': 'time',
    'rate': 'velocity', 'target': 'length', 'seed': None,
}
DEFAULT_TAPER_CYCLES = 1.0
# The longest program (and so the longest block) accepted [s]: 24 h of rig time. Durations, cycle counts and
# frequencies are refused on load when a block would run longer, so everything computed from a program
# (sample counts, setpoint generation, the pre-start limit check) has a bounded cost: a request of
# `cycles: 1e8` or `frequency: 1e-9 Hz` is an error naming the field, not an executor busy for hours.
MAX_PROGRAM_DURATION = 24 * 3600.0
# The lowest frequency of a periodic block [Hz]: one cycle must fit into the longest program.
MIN_FREQUENCY = 1.0 / MAX_PROGRAM_DURATION
# The highest frequency of a periodic block relative to the sample rate it runs at (checked where the rate is
# known: Program.check_sample_rate, called by Limits.check_program and so by every ProgramRunner). A
# servo-hydraulic rig sampled at fs cannot sensibly follow sines above fs/10: at 10 samples per cycle the
# setpoint staircase already misses the peak by up to 5 % (1 - cos(pi/10)), the cycle detector needs at least
# 8 samples per cycle, and closer to fs/2 the command aliases (990 Hz at 1 kHz is a 10 Hz wave).
MAX_FREQUENCY_FRACTION = 0.1


@dataclass
class Block:
    """A validated program block. SI units: m, Hz, s, m/s.

    For periodic blocks (sine, triangle, square, haversine, multisine) `cycles` counts full-amplitude cycles;
    the taper in and out add `taper_cycles` each. For sweeps, `frequency` is the start and `frequency_end` the
    end frequency and `duration` the sweep time at full amplitude. A multisine's `frequency` is its line
    spacing (= repetition rate), its lines the multiples of it from `frequency_start` to `frequency_end`, their
    phases drawn from `seed`. `start_level` is where the block starts (previous block's end). What each
    waveform is: waveform_types.TYPES.
    """

    index: int
    name: str
    waveform: str
    frequency: float = 0.0
    amplitude: float = 0.0
    mean: float = 0.0
    cycles: int = 0
    taper_cycles: float = 0.0
    frequency_end: float = 0.0
    duration: float = 0.0
    rate: float = 0.0
    target: float = 0.0
    start_level: float = 0.0
    frequency_start: float = 0.0
    seed: int = 0
    square_slope: float = field(default=1.0, repr=False)
    detectors: list = field(default_factory=list, repr=False)   # DetectorSpecs of this block only

    # ---- classification
    @property
    def type(self) -> WaveformType:
        """Its waveform's registry entry (waveform_types.TYPES)."""
        return TYPES[self.waveform]

    @property
    def oscillating(self) -> bool:
        """True for blocks with an amplitude and cycles about a mean: the periodic waveforms and the sweeps
        (whose frequency changes, so not periodic).
        """
        return self.type.oscillating

    @property
    def periodic(self) -> bool:
        """True for blocks of whole cycles at one base frequency (they resume after a hold and count cycles)."""
        return self.type.periodic

    def to_dict(self) -> dict:
        """The block as program YAML fields in SI (the inverse of :func:`parse_block`: parsing the result at the
        same start level gives an equal block), for programs rewritten by tools such as ``rubber-rig bench``.
        """
        d = {'name': self.name, 'waveform': self.waveform}
        if self.detectors:
            d['detectors'] = [x.to_dict() for x in self.detectors]
        if self.oscillating:
            d.update(amplitude=self.amplitude, mean=self.mean, taper_cycles=self.taper_cycles)
        d.update(self.type.to_fields(self))
        return d

    @property
    def end_level(self) -> float:
        """Displacement [m] the block ends at."""
        family = self.type.family
        return self.target if family == 'ramp' else self.start_level if family == 'hold' else self.mean

    @property
    def total_cycles(self) -> float:
        """Phase [cycles] at the end of a periodic block, taper included."""
        if self.type.family == 'sweep':
            return wf.sweep_phase(np.array(0.0), self.frequency, self.frequency_end, self.taper_cycles,
                                  self.duration, self.type.log_sweep)[1]
        return self.cycles + 2 * self.taper_cycles

    def seconds(self) -> float:
        """Duration of the block [s]."""
        if self.periodic:
            return self.total_cycles / self.frequency
        if self.type.family == 'sweep':
            return self.taper_cycles / self.frequency + self.duration + self.taper_cycles / self.frequency_end
        return self.duration

    def n_samples(self, sample_rate: float) -> int:
        """Number of samples the block takes at sample_rate [Hz] (ramps include their end point)."""
        n = int(math.ceil(self.seconds() * sample_rate - 1e-9))
        return max(1, n + 1 if self.type.family == 'ramp' else n)

    # ---- evaluation
    def phase(self, t):
        """Phase [cycles] at local times t [s] (periodic blocks)."""
        if self.type.family == 'sweep':
            return wf.sweep_phase(t, self.frequency, self.frequency_end, self.taper_cycles, self.duration,
                                  self.type.log_sweep)[0]
        return self.frequency * t

    def frequency_at(self, t):
        """Instantaneous frequency [Hz] at local times t [s] (0 for hold and ramp)."""
        if self.type.family == 'sweep':
            return wf.sweep_frequency(t, self.frequency, self.frequency_end, self.taper_cycles, self.duration,
                                      self.type.log_sweep)
        return np.full_like(np.asarray(t, dtype=float), self.frequency if self.oscillating else 0.0)

    def unit(self, phase):
        """Tapered unit waveform (-1..1) at phase [cycles]: envelope x shape."""
        return (wf.envelope(phase, self.total_cycles, self.taper_cycles)
                * self.type.shape(self, phase))

    def evaluate_phase(self, phase, gain=1.0, offset=0.0):
        """Setpoint [m] of a periodic block at phase [cycles] (= phase(t)), with gain and offset as evaluate()."""
        return self.mean + offset + gain * self.amplitude * self.unit(phase)

    def evaluate(self, t, gain=1.0, offset=0.0, start_level=None):
        """Setpoint [m] at local times t [s] (array).

        gain scales the amplitude and offset shifts the mean (amplitude control); start_level overrides
        where a ramp starts (resume after hold).
        """
        t = np.asarray(t, dtype=float)
        if self.oscillating:
            return self.evaluate_phase(self.phase(t), gain, offset)
        start = self.start_level if start_level is None else start_level
        if self.type.family == 'hold':
            return np.full_like(t, start)
        return start + (self.target - start) * wf.smoothstep(t / self.duration if self.duration > 0 else 1.0)


def _err(index, name, fld, msg):
    label = f"block {index}" + (f" '{name}'" if name else '')
    return ProgramError(f"{label}: field '{fld}': {msg}" if fld else f'{label}: {msg}')


def parse_block(raw, index: int, start_level: float, defaults: dict) -> Block:
    """Validate one block mapping (after grid expansion) and return a Block starting at start_level [m]."""
    if not isinstance(raw, dict):
        raise _err(index, '', None, f'expected a mapping of fields, got {type(raw).__name__}')
    data = {**defaults, **raw}
    name = data.get('name')
    wave = data.get('waveform')
    if wave is None:
        raise _err(index, name, 'waveform', f"missing (one of: {', '.join(WAVEFORMS)})")
    wave = ALIASES.get(wave, wave)
    if wave not in TYPES:
        raise _err(index, name, 'waveform', f"unknown waveform {data['waveform']!r} "
                                            f"(one of: {', '.join(WAVEFORMS)})")
    name = str(name) if name is not None else f'{wave}_{index}'
    kind = TYPES[wave]
    for key in raw:
        if key == 'detectors':
            continue
        if key not in _FIELDS:
            raise _err(index, name, key, f"unknown field (known: {', '.join(sorted(_FIELDS))})")
        if key not in ('name', 'waveform') and key not in kind.fields:
            raise _err(index, name, key, f"not used by waveform '{wave}' "
                                         f"(allowed: {', '.join(sorted(kind.fields))})")
    values = _si_values(data, kind, index, name)

    def need(key, positive=True):
        if key not in values:
            raise _err(index, name, key, f"required for waveform '{wave}'")
        if positive and values[key] <= 0:
            raise _err(index, name, key, f'must be > 0, got {data[key]!r}')
        return values[key]

    blk = Block(index=index, name=name, waveform=wave, start_level=start_level)
    try:
        blk.detectors = parse_detectors(raw.get('detectors'), f"block {index} '{name}'", index)
    except DetectorError as exc:
        raise ProgramError(str(exc)) from None
    if blk.oscillating:
        _parse_oscillation(blk, values, need)
    kind.parse(blk, values, need, lambda key, msg: _err(index, name, key, msg))
    _check_duration(blk, values)
    return blk


def _si_values(data: dict, kind: WaveformType, index: int, name: str) -> dict:
    """The fields `kind` uses that `data` gives, in SI (cycle counts and seeds whole numbers)."""
    values = {}
    for key in kind.fields:
        if key not in data or data[key] is None:
            continue
        try:
            if key in ('cycles', 'seed'):
                values[key] = _whole_cycles(data[key]) if key == 'cycles' else _seed(data[key])
            elif key == 'taper_cycles':
                values[key] = to_si(data[key], 'number')
            else:
                values[key] = to_si(data[key], _FIELDS[key])
        except ValueError as exc:
            raise _err(index, name, key, str(exc)) from None
    return values


def _parse_oscillation(blk: Block, values: dict, need) -> None:
    """Amplitude, mean and taper of an oscillating block (every such waveform alike)."""
    blk.amplitude = need('amplitude')
    blk.mean = values.get('mean', blk.start_level)
    if abs(blk.mean - blk.start_level) > 1e-12:
        raise _err(blk.index, blk.name, 'mean', f'{blk.mean:g} m differs from the level the previous block ends at '
                                                f'({blk.start_level:g} m): insert a ramp block so nothing steps')
    blk.taper_cycles = values.get('taper_cycles', DEFAULT_TAPER_CYCLES)
    if blk.taper_cycles <= 0:
        raise _err(blk.index, blk.name, 'taper_cycles', 'must be > 0 so the block starts and ends without a '
                                                        'velocity jump')


def _seed(v) -> int:
    """A random seed: a whole number from 0 to 2**32 - 1."""
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < 2 ** 32:
        raise ValueError(f'expected a whole number from 0 to {2 ** 32 - 1}, got {v!r}')
    return int(v)


def _whole_cycles(v) -> int:
    """A cycle count: a whole, finite number >= 1 (YAML .inf, 2.5 or '8' are refused before any int())."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f'expected a whole number of cycles, got {v!r}')
    if isinstance(v, float) and not math.isfinite(v):
        raise ValueError(f'must be a finite whole number of cycles, got {v!r}')
    if abs(v) > 1e15:      # far beyond any program that fits MAX_PROGRAM_DURATION; keeps int/float exact
        raise ValueError(f'{str(v)[:12]}{"..." if len(str(v)) > 12 else ""} cycles are far more than fit '
                         f'into the longest program ({MAX_PROGRAM_DURATION / 3600:g} h)')
    if v != int(v):
        raise ValueError(f'expected a whole number of cycles, got {v!r}')
    return int(v)


def _check_duration(blk: Block, values: dict) -> None:
    """Refuse a block that cannot run within MAX_PROGRAM_DURATION, naming the field that makes it too long."""
    hours = f'{MAX_PROGRAM_DURATION / 3600:g} h'
    frequencies = blk.type.frequencies(blk)
    for key, f in frequencies:
        if f < MIN_FREQUENCY:
            raise _err(blk.index, blk.name, key, f'{f:.6g} Hz is below the lowest frequency {MIN_FREQUENCY:.6g} Hz: '
                                                 f'one cycle would take longer than the longest program ({hours})')
    seconds = blk.seconds()
    if math.isfinite(seconds) and seconds <= MAX_PROGRAM_DURATION:
        return
    if blk.periodic:        # the larger part of the block is to blame
        key = 'cycles' if blk.cycles >= 2 * blk.taper_cycles else 'taper_cycles'
    elif blk.type.family == 'sweep':
        tapers = blk.taper_cycles / blk.frequency + blk.taper_cycles / blk.frequency_end
        key = 'duration' if blk.duration >= tapers else 'taper_cycles'
    else:
        key = 'rate' if 'rate' in values else 'duration'
    raise _err(blk.index, blk.name, key, f'the block would run {seconds:.6g} s, longer than the longest program '
                                         f'({MAX_PROGRAM_DURATION:g} s = {hours})')
