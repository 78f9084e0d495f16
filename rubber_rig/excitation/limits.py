"""Safety limits on displacement, velocity and force, checked before a program starts and on every setpoint."""
import math
from dataclasses import dataclass, asdict
from typing import Optional

import numpy as np


class LimitError(ValueError):
    """A program or setpoint would leave the safe envelope; the message names the limit and where."""


@dataclass
class Limits:
    """Safe envelope, SI: displacement_min/max [m], velocity_max [m/s], force_max [N] (absolute).

    stiffness_estimate [N/m], if given, lets the pre-start check predict the peak force k * |x|."""
    displacement_min: float = -5e-3
    displacement_max: float = 5e-3
    velocity_max: float = 0.2
    force_max: float = 60e3
    stiffness_estimate: Optional[float] = None

    def __post_init__(self):
        for name in ('displacement_min', 'displacement_max', 'velocity_max', 'force_max'):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise LimitError(f"limits: field '{name}': expected a finite number, got {v!r}")
        if self.displacement_min >= self.displacement_max:
            raise LimitError(f"limits: field 'displacement_min': {self.displacement_min:g} m must be below "
                             f"displacement_max {self.displacement_max:g} m")
        for name in ('velocity_max', 'force_max'):
            if getattr(self, name) <= 0:
                raise LimitError(f"limits: field '{name}': must be > 0")

    @classmethod
    def from_dict(cls, data) -> 'Limits':
        """Build from a mapping; unknown keys are an error naming the key."""
        if data is None:
            return cls()
        if isinstance(data, Limits):
            return data
        if not isinstance(data, dict):
            raise LimitError(f'limits: expected a mapping, got {type(data).__name__}')
        known = set(cls.__dataclass_fields__)
        for key in data:
            if key not in known:
                raise LimitError(f"limits: field '{key}': unknown (known: {', '.join(sorted(known))})")
        return cls(**data)

    def to_dict(self) -> dict:
        return asdict(self)

    def clamp_position(self, x: float) -> float:
        """x [m] moved inside the displacement range."""
        return min(max(x, self.displacement_min), self.displacement_max)

    def check_setpoints(self, x, sample_rate: float, previous: Optional[float] = None, where: str = 'setpoint'):
        """Raise LimitError if setpoints x [m] (shape (n,)) leave the displacement range or their velocity
        (finite difference at sample_rate [Hz], starting from `previous` if given) exceeds velocity_max."""
        x = np.asarray(x, dtype=float)
        if x.size == 0:
            return
        if not np.all(np.isfinite(x)):
            raise LimitError(f'{where}: not finite')
        lo, hi = float(x.min()), float(x.max())
        if lo < self.displacement_min - 1e-12 or hi > self.displacement_max + 1e-12:
            raise LimitError(f'{where}: displacement {lo:.6g}..{hi:.6g} m outside the limits '
                             f'{self.displacement_min:g}..{self.displacement_max:g} m')
        seq = x if previous is None else np.concatenate([[previous], x])
        if seq.size > 1:
            v = float(np.max(np.abs(np.diff(seq)))) * sample_rate
            if v > self.velocity_max * (1 + 1e-9):
                raise LimitError(f'{where}: velocity {v:.6g} m/s above velocity_max {self.velocity_max:g} m/s')

    def check_program(self, program, sample_rate: float):
        """Check every setpoint of `program` (open loop) at sample_rate [Hz] before it starts, block by block,
        so the error names the block. Also predicts peak force if stiffness_estimate is set."""
        starts = program.block_starts(sample_rate)
        prev = program.initial_position
        if not self.displacement_min <= prev <= self.displacement_max:
            raise LimitError(f'program {program.name!r}: initial_position {prev:g} m outside the limits')
        if not self.displacement_min <= program.rest_position <= self.displacement_max:
            raise LimitError(f'program {program.name!r}: rest_position {program.rest_position:g} m outside '
                             f'the limits')
        chunk = 1 << 18
        for i, blk in enumerate(program.blocks):
            where = f"program {program.name!r} block {i} '{blk.name}'"
            for lo in range(int(starts[i]), int(starts[i + 1]), chunk):
                x = program.setpoints(sample_rate, lo, min(lo + chunk, int(starts[i + 1])))
                self.check_setpoints(x, sample_rate, prev, where)
                if self.stiffness_estimate:
                    f = self.stiffness_estimate * float(np.max(np.abs(x)))
                    if f > self.force_max:
                        raise LimitError(f'{where}: predicted force {f:.6g} N (stiffness_estimate x |x|) above '
                                         f'force_max {self.force_max:g} N')
                prev = float(x[-1])
