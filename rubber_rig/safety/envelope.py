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


"""The safe envelope (displacement, velocity, force, braking) and the one check every setpoint passes.

`setpoint_violation` is the rule; rig_driver applies it to every streamed batch (a violation faults the rig),
`Limits.check_setpoints` raises it as a LimitError for the program pre-check (excitation.limits.check_program).
Both use the same tolerances, defined here once:

* RANGE_SLACK [m]: a setpoint may exceed a displacement limit by rounding only;
* VELOCITY_SLACK (relative): the finite-difference velocity may exceed velocity_max by rounding only;
* STOP_SLACK [m]: where an abort braking at deceleration_max stops (ramp.stopping_positions) may exceed a limit
  by rounding only.
"""
import math
from dataclasses import dataclass, field, fields
from typing import Callable, Optional

import numpy as np

from ..settings import setting, violations
from .ramp import DECEL_MAX, RAMP_VELOCITY, stopping_positions

RANGE_SLACK = 1e-12
VELOCITY_SLACK = 1e-9
STOP_SLACK = 1e-9


class LimitError(ValueError):
    """A program or setpoint would leave the safe envelope; the message names the limit and where. `field`: the
    Limits field a bad configuration value concerns ('' for a program or setpoint outside the envelope).
    """

    def __init__(self, message: str, field: str = ''):
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class Violation:
    """Why setpoints leave the envelope. kind: 'not_finite', 'displacement', 'velocity' or 'stopping';
    index: the first offending sample of the batch; message: what, with the numbers.
    """

    kind: str
    index: int
    message: str


@dataclass
class Limits:
    """Safe envelope, SI: displacement_min/max [m], velocity_max [m/s], force_max [N] (absolute),
    deceleration_max [m/s^2]: the hardest braking an abort ramp may use, so every setpoint must be able to stop
    inside the displacement range at it (ramp.stopping_positions) - then an abort at any phase stays inside.

    stiffness_estimate [N/m], if given, lets the pre-start check predict the peak force k * |x|; force_model, if
    given, is a callable block -> predicted peak |force| [N] that the pre-start check asks for every block
    (see excitation.limits.element_force_model); check_program(force_model=...) overrides it for one check.
    """

    displacement_min: float = setting(-5e-3, 'lowest allowed displacement', units='m', range=(-1.0, 1.0))
    displacement_max: float = setting(5e-3, 'highest allowed displacement', units='m', range=(-1.0, 1.0))
    velocity_max: float = setting(0.2, 'highest allowed velocity (an abort ramp travels at half of it, at most '
                                  'RAMP_VELOCITY, in whole mm/s as the CAN frame carries it)', units='m/s',
                                  range=(2e-3, 100.0))
    force_max: float = setting(60e3, 'highest allowed absolute force', units='N', range=(1.0, 1e7))
    deceleration_max: float = setting(DECEL_MAX, 'hardest braking of a ramp; every setpoint must be able to stop '
                                      'inside the displacement limits at it (the CAN frame carries multiples of '
                                      '2 m/s^2)', units='m/s^2', range=(2.0, 510.0))
    stiffness_estimate: Optional[float] = None
    force_model: Optional[Callable] = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        for name in ('displacement_min', 'displacement_max', 'velocity_max', 'force_max', 'deceleration_max'):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise LimitError(f"limits: field '{name}': expected a finite number, got {v!r}", name)
        if self.displacement_min >= self.displacement_max:
            raise LimitError(f"limits: field 'displacement_min': {self.displacement_min:g} m must be below "
                             f"displacement_max {self.displacement_max:g} m", 'displacement_min')
        for name, why in violations(self):     # the ranges of the settings above: the one place they are written
            raise LimitError(f"limits: field '{name}': {why}", name)
        k = self.stiffness_estimate
        if k is not None and (isinstance(k, bool) or not isinstance(k, (int, float)) or not math.isfinite(k)
                              or k < 0):
            raise LimitError(f"limits: field 'stiffness_estimate': expected a finite stiffness >= 0 [N/m], "
                             f"got {k!r}", 'stiffness_estimate')
        if self.force_model is not None and not callable(self.force_model):
            raise LimitError(f"limits: field 'force_model': expected a callable block -> peak force [N], got "
                             f"{type(self.force_model).__name__}")

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
                raise LimitError(f"limits: field '{key}': unknown (known: {', '.join(sorted(known))})", key)
        return cls(**data)

    def to_dict(self) -> dict:
        """The numeric fields (not the force model)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != 'force_model'}

    def clamp_position(self, x: float) -> float:
        """X [m] moved inside the displacement range."""
        return min(max(x, self.displacement_min), self.displacement_max)

    def check_setpoints(self, x, sample_rate: float, previous: Optional[float] = None, where: str = 'setpoint'):
        """Raise LimitError if setpoints x [m] (shape (n,)) leave the envelope (setpoint_violation)."""
        bad = setpoint_violation(self, x, sample_rate, previous)
        if bad is not None:
            raise LimitError(f'{where}: {bad.message}')

    def check_range(self, lo: float, hi: float, where: str):
        """Raise LimitError if displacements lo..hi [m] leave the displacement range."""
        if _outside_range(self, lo, hi):
            raise LimitError(f'{where}: {_range_message(self, lo, hi)}')

    def check_velocity(self, v: float, where: str):
        """Raise LimitError if speed v [m/s] exceeds velocity_max."""
        if _too_fast(self, v):
            raise LimitError(f'{where}: {_velocity_message(self, v)}')

    def check_stiffness_force(self, peak_x: float, where: str):
        """Raise LimitError if stiffness_estimate [N/m] x peak |x| [m] exceeds force_max."""
        if self.stiffness_estimate:
            f = self.stiffness_estimate * peak_x
            if f > self.force_max:
                raise LimitError(f'{where}: predicted force {f:.6g} N (stiffness_estimate x |x|) above '
                                 f'force_max {self.force_max:g} N')


def abort_ramp_velocity(limits: Limits) -> float:
    """Travel speed [m/s] of an abort or hold ramp under `limits`: half velocity_max, at most RAMP_VELOCITY."""
    return min(0.5 * limits.velocity_max, RAMP_VELOCITY)


def setpoint_violation(limits: Limits, x, sample_rate: float, previous: Optional[float] = None):
    """The first way setpoints x [m] (shape (n,)) at sample_rate [Hz] leave the envelope, or None.

    Checked in this order: every value finite; inside displacement_min..max; the finite-difference velocity
    (from `previous` [m], if given) at most velocity_max; and every setpoint able to stop inside the range when
    an abort brakes at deceleration_max from the next sample on (ramp.stopping_positions).
    """
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return None
    finite = np.isfinite(x)
    if not np.all(finite):
        k = int(np.argmin(finite))
        return Violation('not_finite', k, f'setpoint {float(x[k])} at sample {k} is not finite')
    lo, hi = float(x.min()), float(x.max())
    if _outside_range(limits, lo, hi):
        k = int(np.argmax(np.maximum(limits.displacement_min - x, x - limits.displacement_max)))
        return Violation('displacement', k, _range_message(limits, lo, hi))
    seq = x if previous is None else np.concatenate([[float(previous)], x])
    if seq.size < 2:
        return None
    v = np.diff(seq) * sample_rate
    offset = x.size - v.size                     # v[i] is the velocity reaching x[i + offset]
    speed = np.abs(v)
    k = int(np.argmax(speed))
    if _too_fast(limits, float(speed[k])):
        return Violation('velocity', k + offset, _velocity_message(limits, float(speed[k])))
    stop = stopping_positions(seq[1:], v, limits.deceleration_max, sample_rate)
    over = np.maximum(limits.displacement_min - stop, stop - limits.displacement_max)
    k = int(np.argmax(over))
    if over[k] > STOP_SLACK:
        return Violation('stopping', k + offset,
                         f'setpoint {seq[k + 1] * 1e3:.4f} mm at {v[k]:.4g} m/s could not stop inside the limits at '
                         f'deceleration_max {limits.deceleration_max:g} m/s^2 (an abort would stop at '
                         f'{stop[k] * 1e3:.4f} mm; limits {limits.displacement_min * 1e3:g}..'
                         f'{limits.displacement_max * 1e3:g} mm)')
    return None


def _outside_range(limits: Limits, lo: float, hi: float) -> bool:
    return lo < limits.displacement_min - RANGE_SLACK or hi > limits.displacement_max + RANGE_SLACK


def _too_fast(limits: Limits, v: float) -> bool:
    return not v <= limits.velocity_max * (1 + VELOCITY_SLACK)     # (NaN is too fast)


def _range_message(limits: Limits, lo: float, hi: float) -> str:
    return (f'displacement {lo:.6g}..{hi:.6g} m outside the displacement limits '
            f'{limits.displacement_min:g}..{limits.displacement_max:g} m')


def _velocity_message(limits: Limits, v: float) -> str:
    return f'velocity {v:.6g} m/s above velocity_max {limits.velocity_max:g} m/s'
