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

"""What the reference controller moves and measures: its ramps to rest (docs/protocol.md "States": from the
present command and velocity, never a step, inside HostLimits, braking at most at HL_Deceleration) and the rig
it stands for: an ideal position loop on a reference spring (a proving device, cf. ISO 7500-1), with load-cell
and transducer noise and the measurement defects of defects.py.
"""
from __future__ import annotations

import math

import numpy as np

TRAVEL_ACCEL = 2.0          # [m/s^2] acceleration of a ramp's travel
BRAKE_DECEL = 20.0          # [m/s^2] braking of a ramp, or HL_Deceleration when that is lower
OWN_RAMP_VELOCITY = 0.02    # [m/s] travel of the controller's own ramps (faults, host silence): the specification
#                             bounds them at 0.05 m/s
STEP_DEFECT = 0.5e-3        # [m] defect fault_ramp_step: first step of an own ramp
OVERSHOOT_DEFECT = 0.2e-3   # [m] defect fault_ramp_overshoot: own ramps pass their target by this much


class Ramp:
    """A ramp from command u [m] moving at velocity v [m/s] to `target` (None: brake to a stop), travelling at
    most at `velocity` [m/s] and braking at `decel` [m/s^2]; step(fs) -> the next command, `done` at the end.
    `first_step` [m] (defect) jumps towards the target at once; `past` [m] (defect) aims beyond it first.
    """

    def __init__(self, u: float, v: float, target, velocity: float, decel: float, first_step: float = 0.0,
                 past: float = 0.0):
        self.u, self.v, self.velocity, self.decel = u, v, velocity, decel
        self.target = target
        self.then = None
        if target is not None and past and abs(target - u) > 1e-6:
            self.target, self.then = target + math.copysign(past, target - u), target
        if target is not None and first_step:
            self.u += max(-first_step, min(first_step, target - u))
        self.done = False

    def step(self, fs: float) -> float:
        dt = 1.0 / fs
        if self.target is None:           # HOLD: brake at decel to a stop where the motion can stop
            dv = self.decel * dt
            self.v = 0.0 if abs(self.v) <= dv else self.v - math.copysign(dv, self.v)
            self.u += self.v * dt
            self.done = self.v == 0.0
            return self.u
        d = self.target - self.u
        wanted = math.copysign(min(self.velocity, math.sqrt(2.0 * self.decel * abs(d))), d)
        braking = abs(wanted) < abs(self.v) or wanted * self.v < 0
        limit = (self.decel if braking else TRAVEL_ACCEL) * dt
        self.v += max(-limit, min(limit, wanted - self.v))
        step = self.v * dt
        if abs(step) >= abs(d) and step * d >= 0:     # arrives within this tick
            self.u, self.v = self.target, 0.0
            if self.then is not None:
                self.target, self.then = self.then, None
            else:
                self.done = True
        else:
            self.u += step
        return self.u


class Plant:
    """An ideal position loop (the measured displacement follows the command) on a linear reference spring of
    `stiffness` [N/m], with noise of `x_noise` [m] and `f_noise` [N] (seeded: runs repeat), and the measurement
    defects named in `defects`. measure(u) -> (displacement [m], force [N]) reported for the tick.
    """

    def __init__(self, stiffness: float, defects=frozenset(), x_noise: float = 2e-8, f_noise: float = 2.0,
                 seed: int = 36):
        self.k, self.defects = float(stiffness), frozenset(defects)
        self.x_noise, self.f_noise = x_noise, f_noise
        self.rng = np.random.default_rng(seed)
        self._f_before = 0.0

    def measure(self, u: float) -> tuple[float, float]:
        x_read = u + self.rng.normal(0.0, self.x_noise)
        # the loop closes on the transducer: with a gain of 1.3 it reads the command while the spring sees 1/1.3
        x_true = x_read / 1.3 if 'displacement_gain_1_3' in self.defects else x_read
        force = self.k * x_true + self.rng.normal(0.0, self.f_noise)
        if 'force_one_sample_late' in self.defects:
            force, self._f_before = self._f_before, force
        if 'force_sign_inverted' in self.defects:
            force = -force
        if 'force_in_kN' in self.defects:
            force /= 1000.0
        return x_read, force
