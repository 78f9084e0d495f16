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

"""Test programs: an ordered list of blocks loaded from YAML and validated on load.

Bounded by construction, so no request can occupy the excitation for long: the YAML text is at most
MAX_BYTES long, nests at most 32 deep and expands its aliases to at most 100 000 nodes (checked by
yamltext.load_bounded before the document is built); at most MAX_BLOCKS blocks (grids included) and
MAX_PROGRAM_DURATION (24 h) of rig time, every number finite, every block frequency at least MIN_FREQUENCY;
the sample-rate rule (f <= MAX_FREQUENCY_FRACTION * fs, i.e. fs/10) is checked by Program.check_sample_rate
where the rate is known (Limits.check_program, ProgramRunner).
"""
import dataclasses
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import List

import numpy as np
import yaml

from rubber_rig.units import to_si

from .blocks import (  # noqa: F401 - MIN_FREQUENCY, MAX_FREQUENCY_FRACTION are part of this module's API
    MAX_FREQUENCY_FRACTION,
    MAX_PROGRAM_DURATION,
    MIN_FREQUENCY,
    Block,
    ProgramError,
    parse_block,
)
from .detector_specs import DetectorError, parse_detectors
from .yamltext import YAMLLimitError, load_bounded, read_bounded_file

PROGRAM_DIR = Path(__file__).with_name('programs')
# The shipped programs are named by what they test; recordings made before carry the names of the papers they
# came from, so those names still load the same program (and nothing else may take them).
PROGRAM_ALIASES = {'seed000_grid': 'dynamic_stiffness_grid', 'seed001_bushing': 'quasi_static_then_sine',
                   'seed003_sweeps': 'log_sweeps_1_50hz', 'seed004_preload': 'preload_sine_grid'}
# The most blocks a program may have (after grid expansion): far above any real test plan
# (dynamic_stiffness_grid has 22), low enough that parsing and checking a program stays well below half a second
# (bench_checks.py).
MAX_BLOCKS = 2000
_TOP_FIELDS = {'name', 'description', 'source', 'initial_position', 'rest_position', 'defaults', 'blocks',
               'detectors'}


@dataclass
class Program:
    """A validated test program. `blocks` are in run order; positions are SI [m]."""

    name: str
    blocks: List[Block]
    description: str = ''
    initial_position: float = 0.0   # where the actuator is when the program starts [m]
    rest_position: float = 0.0      # where an abort ramps to [m]
    source: str = ''
    detectors: list = field(default_factory=list)   # DetectorSpecs of the whole program (blocks add their own)
    _starts: dict = field(default_factory=dict, repr=False)

    @classmethod
    def from_yaml_text(cls, text: str, name: str = '') -> 'Program':
        """Parse and validate a program from YAML text. Raises ProgramError naming block and field."""
        try:
            data = load_bounded(text, f'program {name or "<text>"}')
        except YAMLLimitError as exc:
            raise ProgramError(str(exc)) from None
        except yaml.YAMLError as exc:
            raise ProgramError(f'program {name or "<text>"}: not valid YAML: {exc}') from None
        return cls.from_dict(data, name=name)

    @classmethod
    def from_dict(cls, data, name: str = '') -> 'Program':
        """Validate a program given as a mapping {name, description, initial_position, defaults, blocks}."""
        if not isinstance(data, dict):
            raise ProgramError(f'program {name or "<text>"}: expected a mapping with a \'blocks\' list')
        for key in data:
            if key not in _TOP_FIELDS:
                raise ProgramError(f"program: field '{key}': unknown (known: {', '.join(sorted(_TOP_FIELDS))})")
        name = str(data.get('name') or name or 'program')
        positions = {}
        for key in ('initial_position', 'rest_position'):
            try:
                positions[key] = to_si(data.get(key, 0.0), 'length')
            except ValueError as exc:
                raise ProgramError(f"program '{name}': field '{key}': {exc}") from None
        defaults = data.get('defaults') or {}
        if not isinstance(defaults, dict):
            raise ProgramError(f"program '{name}': field 'defaults': expected a mapping")
        raw_blocks = data.get('blocks')
        if not isinstance(raw_blocks, list) or not raw_blocks:
            raise ProgramError(f"program '{name}': field 'blocks': expected a non-empty list of blocks")
        blocks, level, seconds = [], positions['initial_position'], 0.0
        for raw in raw_blocks:
            for expanded in _expand_grid(raw, len(blocks)):
                blk = parse_block(expanded, len(blocks), level, defaults)
                blocks.append(blk)
                level = blk.end_level
                seconds += blk.seconds()
                if seconds > MAX_PROGRAM_DURATION:
                    raise ProgramError(f"program '{name}': block {blk.index} '{blk.name}': the program would run "
                                       f"longer than {MAX_PROGRAM_DURATION:g} s ({MAX_PROGRAM_DURATION / 3600:g} h), "
                                       f"the longest accepted")
        try:
            detectors = parse_detectors(data.get('detectors'), f"program '{name}'")
        except DetectorError as exc:
            raise ProgramError(str(exc)) from None
        return cls(name=name, blocks=blocks, description=str(data.get('description', '')),
                   source=str(data.get('source', '')), detectors=detectors, **positions)

    def all_detectors(self) -> list:
        """The program's detectors followed by every block's own (each knows its block: -1 = all)."""
        return list(self.detectors) + [d for b in self.blocks for d in b.detectors]

    def check_sample_rate(self, sample_rate: float) -> None:
        """Raise ProgramError unless the program can run at sample_rate [Hz]: a finite positive rate, every
        periodic block's highest frequency at most MAX_FREQUENCY_FRACTION * sample_rate (fs/10, see blocks.py)
        and at most MAX_PROGRAM_DURATION of samples. Cost: one pass over the blocks.
        """
        fs = sample_rate
        if isinstance(fs, bool) or not isinstance(fs, (int, float)) or not math.isfinite(fs) or fs <= 0:
            raise ProgramError(f'program {self.name!r}: sample rate {fs!r} Hz must be a finite number > 0')
        f_max = MAX_FREQUENCY_FRACTION * fs
        seconds = 0.0
        for blk in self.blocks:
            for key, f in _frequency_fields(blk):
                if not f <= f_max:
                    raise ProgramError(f"block {blk.index} '{blk.name}': field '{key}': {f:g} Hz is above "
                                       f"{f_max:g} Hz, the highest frequency at a sample rate of {fs:g} Hz "
                                       f"(sample_rate/{1 / MAX_FREQUENCY_FRACTION:g}: at least "
                                       f"{1 / MAX_FREQUENCY_FRACTION:g} samples per cycle)")
            seconds += blk.seconds()
        if not seconds <= MAX_PROGRAM_DURATION:
            raise ProgramError(f'program {self.name!r}: runs {seconds:.6g} s, longer than {MAX_PROGRAM_DURATION:g} s '
                               f'({MAX_PROGRAM_DURATION / 3600:g} h), the longest accepted')

    # ---- timing
    def copy(self) -> 'Program':
        """A copy whose block list (and its cached block starts) can change without touching this one (a resumed
        block runs only the cycles it still owes: ProgramRunner.resume_at).
        """
        return dataclasses.replace(self, blocks=list(self.blocks), detectors=list(self.detectors), _starts={})

    def block_starts(self, sample_rate: float) -> np.ndarray:
        """Program sample index at which each block starts, plus the total as last element (shape n+1)."""
        key = float(sample_rate)
        if key not in self._starts:
            counts = [b.n_samples(sample_rate) for b in self.blocks]
            self._starts[key] = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return self._starts[key]

    def n_samples(self, sample_rate: float) -> int:
        """Total number of setpoint samples at sample_rate [Hz]."""
        return int(self.block_starts(sample_rate)[-1])

    def duration(self, sample_rate: float = 1000.0) -> float:
        """Program duration [s] at sample_rate [Hz] (whole samples)."""
        return self.n_samples(sample_rate) / sample_rate

    def setpoints(self, sample_rate: float, start: int = 0, stop: int = None) -> np.ndarray:
        """Open-loop setpoints [m] for program samples start..stop-1 (no amplitude control), shape (n,)."""
        starts = self.block_starts(sample_rate)
        stop = int(starts[-1]) if stop is None else min(stop, int(starts[-1]))
        out = np.empty(max(stop - start, 0))
        for i, blk in enumerate(self.blocks):
            lo, hi = max(start, starts[i]), min(stop, starts[i + 1])
            if lo < hi:
                out[lo - start:hi - start] = blk.evaluate((np.arange(lo, hi) - starts[i]) / sample_rate)
        return out


class OverrideError(ValueError):
    """An invalid override of :func:`with_overrides`; ``field`` names it ('cycles', 'blocks', ...)."""

    def __init__(self, field: str, why: str):
        super().__init__(f'{field}: {why}')
        self.field, self.why = field, why


def select_blocks(spec: str, n: int) -> list[int]:
    """Block indices of a selection like ``'0-3,7'`` among ``n`` blocks, in the order given."""
    out = []
    for part in spec.split(','):
        part = part.strip()
        if not part:
            continue
        lo, _, hi = part.partition('-')
        try:
            a, b = int(lo), int(hi) if hi else int(lo)
        except ValueError:
            raise OverrideError('blocks', f'{part!r} is not an index or a range like 0-3') from None
        if not (0 <= a <= b < n):
            raise OverrideError('blocks', f"{part!r} outside the program's blocks 0-{n - 1}")
        out.extend(range(a, b + 1))
    return out


def with_overrides(program: Program, cycles: int = None, duration_scale: float = None, blocks: str = None,
                   taper_cycles: float = None, note: str = 'rewritten') -> tuple[Program, str]:
    """(Program, YAML text) of ``program`` rewritten: only the ``blocks`` selected (see :func:`select_blocks`),
    ``cycles`` full-amplitude cycles per periodic block, cycle counts and hold/sweep durations scaled by
    ``duration_scale`` (tapers and ramps kept), ``taper_cycles`` for every oscillating block. The result is
    validated like any program; OverrideError names the override at fault. ``note`` is appended to the
    description in parentheses.
    """
    if cycles is not None and cycles < 1:
        raise OverrideError('cycles', f'must be >= 1, got {cycles}')
    if duration_scale is not None and not duration_scale > 0:
        raise OverrideError('duration_scale', f'must be > 0, got {duration_scale}')
    if taper_cycles is not None and not taper_cycles > 0:
        raise OverrideError('taper_cycles', f'must be > 0, got {taper_cycles}')
    chosen = program.blocks if not blocks else [program.blocks[i] for i in select_blocks(blocks, len(program.blocks))]
    out = []
    for blk in chosen:
        d = blk.to_dict()
        if 'cycles' in d:
            if cycles is not None:
                d['cycles'] = cycles
            if duration_scale:
                d['cycles'] = max(1, int(round(d['cycles'] * duration_scale)))
        elif 'duration' in d and duration_scale and blk.type.family != 'ramp':
            d['duration'] *= duration_scale
        if 'taper_cycles' in d and taper_cycles is not None:
            d['taper_cycles'] = taper_cycles
        out.append(d)
    data = {'name': program.name, 'description': f'{program.description} ({note})'.strip(),
            'initial_position': program.initial_position, 'rest_position': program.rest_position, 'blocks': out}
    if program.detectors:
        data['detectors'] = [d.to_dict() for d in program.detectors]
    text = yaml.safe_dump(data, sort_keys=False)
    return Program.from_yaml_text(text, name=program.name), text


def _expand_grid(raw, first_index):
    """A block whose 'amplitude' and/or 'frequency' is a list stands for the grid of all combinations
    (amplitude outer, frequency inner), named <name>_<A>mm_<f>Hz.
    """
    if first_index >= MAX_BLOCKS:
        raise ProgramError(f'block {first_index}: the program has more than {MAX_BLOCKS} blocks')
    if not isinstance(raw, dict):
        return [raw]
    grid_keys = [k for k in ('amplitude', 'frequency') if isinstance(raw.get(k), list)]
    if not grid_keys:
        return [raw]
    count = 1
    for k in grid_keys:
        if not raw[k]:
            raise ProgramError(f"block {first_index} '{raw.get('name', '')}': field '{k}': empty list")
        count *= len(raw[k])
    if first_index + count > MAX_BLOCKS:   # before expanding: a 1000 x 1000 grid is a short text
        raise ProgramError(f"block {first_index} '{raw.get('name', '')}': field '{grid_keys[-1]}': the grid "
                           f"({' x '.join(str(len(raw[k])) for k in grid_keys)}) would take the program to "
                           f"{first_index + count} blocks, more than {MAX_BLOCKS}")
    out = []
    base = raw.get('name') or raw.get('waveform', 'block')
    for combo in itertools.product(*(raw[k] for k in grid_keys)):
        blk = dict(raw)
        blk.update(zip(grid_keys, combo, strict=False))
        parts = []
        for k, v in zip(grid_keys, combo, strict=False):
            try:
                si = to_si(v, 'length' if k == 'amplitude' else 'frequency')
                parts.append(f'{si * 1e3:g}mm' if k == 'amplitude' else f'{si:g}Hz')
            except ValueError:
                parts.append(str(v))
        blk['name'] = '_'.join([str(base)] + parts)
        out.append(blk)
    return out


def _frequency_fields(blk: Block):
    """(field, frequency [Hz]) of the frequencies a block runs at (none for hold and ramp)."""
    return blk.type.frequencies(blk)


def program_source(path_or_name) -> tuple[str, str]:
    """(YAML text, name) of a program given as a YAML path or the name of a shipped program."""
    path = Path(path_or_name)
    if not path.suffix and not path.exists():
        path = PROGRAM_DIR / f'{PROGRAM_ALIASES.get(str(path_or_name), path_or_name)}.yaml'
    if not path.exists():
        raise FileNotFoundError(f'no program {str(path_or_name)!r} (shipped programs: '
                                f'{", ".join(shipped_programs())})')
    try:
        return read_bounded_file(path, f'program {str(path)!r}'), path.stem
    except YAMLLimitError as exc:
        raise ProgramError(str(exc)) from None


def read_program(path: str = '', yaml_text: str = '') -> tuple[Program, str]:
    """(validated Program, its YAML text) from a file path or shipped name, or else from YAML text (a goal's
    or a service request's two ways of giving a program).
    """
    if path:
        text, name = program_source(path)
        return Program.from_yaml_text(text, name=name), text
    if not yaml_text.strip():
        raise ValueError('no program: give program_path or program_yaml')
    return Program.from_yaml_text(yaml_text, name='goal'), yaml_text


def load_program(path_or_name) -> Program:
    """Load a program from a YAML path, or by name from the shipped programs (e.g. "dynamic_stiffness_grid")."""
    text, name = program_source(path_or_name)
    return Program.from_yaml_text(text, name=name)


def shipped_programs() -> List[str]:
    """Names of the programs shipped with the package."""
    return sorted(p.stem for p in PROGRAM_DIR.glob('*.yaml'))
